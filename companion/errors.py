"""The one exception type for a user's mistake (bad file, bad flag, unreachable vehicle).

Raised anywhere, caught once in :mod:`companion.cli`, printed as a single line and turned into a
non-zero exit code: never a traceback for a user's error.
"""

import math


class UserError(Exception):
    """A problem the user can fix; ``str(err)`` is the one-line message, ``exit_code`` the code."""

    def __init__(self, message: str, exit_code: int = 2):
        super().__init__(message)
        self.exit_code = exit_code


def require_positive(flag: str, value: float | None, minimum: float = 0.0) -> None:
    """A flag's number must be finite and above ``minimum`` (``None``: not given, fine)."""
    if value is not None and not (math.isfinite(value) and value > minimum):
        raise UserError(f"{flag} must be a number > {minimum:g}, not {value!r}")
