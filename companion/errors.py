"""The one exception type for a user's mistake (bad file, bad flag, unreachable vehicle), and the
exit codes every command returns.

Raised anywhere, caught once in :mod:`companion.cli`, printed as a single line and turned into a
non-zero exit code: never a traceback for a user's error.
"""

import math
from enum import IntEnum


class ExitCode(IntEnum):
    """What a ``companion`` process's exit status means, stated once (docs/flying.md lists it).

    The systemd unit (``deploy/pzc-rover.service``) restarts on none of USER_ERROR and FAULT:
    ``RestartPreventExitStatus`` names exactly those (``tests/test_deploy.py`` holds it).
    """

    OK = 0              # mission done, or stopped on request (SIGTERM, Ctrl-C, abort) after
                        # stopping the rover; a check that passed
    CHECK_FAILED = 1    # preflight or pki found a problem (the report says which)
    USER_ERROR = 2      # a user's mistake: bad flag or file, no vehicle, no telemetry, a
                        # mission the vehicle cannot start; nothing moved because of it
    FAULT = 3           # a run stopped by a fault: telemetry lost, vehicle restarted, mode or
                        # arming refused, pilot took over, a non-finite command
    OUT_OF_REACH = 3    # `mission check --vehicle`: the mission asks more than the vehicle can
    INTERRUPTED = 130   # Ctrl-C before anything was flying (128 + SIGINT, as a shell reports)


class UserError(Exception):
    """A problem the user can fix; ``str(err)`` is the one-line message, ``exit_code`` the code."""

    def __init__(self, message: str, exit_code: int = ExitCode.USER_ERROR):
        super().__init__(message)
        self.exit_code = exit_code


def require_positive(flag: str, value: float | None, minimum: float = 0.0) -> None:
    """A flag's number must be finite and above ``minimum`` (``None``: not given, fine)."""
    if value is not None and not (math.isfinite(value) and value > minimum):
        raise UserError(f"{flag} must be a number > {minimum:g}, not {value!r}")
