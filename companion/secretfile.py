"""Reading a secret from a file (MAVLink signing key, Zenoh control secret) safely.

A secret that other users can read is no secret: the file must be a regular file with no
group or other permissions. Every problem is a one-line :class:`UserError` naming the flag
and the file.
"""

from __future__ import annotations

import os
import stat

from .errors import UserError


def read_private(path: str, flag: str, what: str, max_bytes: int) -> bytes:
    """Up to ``max_bytes`` of ``path``, after checking it is a private regular file."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise UserError(f"{flag} {path}: no such file") from None
    except OSError as exc:
        raise UserError(f"{flag} {path}: cannot read: {exc.strerror}") from None
    if not stat.S_ISREG(st.st_mode):
        raise UserError(f"{flag} {path}: not a regular file")
    if st.st_mode & 0o077:
        raise UserError(f"{flag} {path}: other users can access the {what} (mode "
                        f"{stat.S_IMODE(st.st_mode):04o}); run: chmod 600 {path}")
    try:
        with open(path, "rb") as f:
            return f.read(max_bytes)
    except OSError as exc:
        raise UserError(f"{flag} {path}: cannot read: {exc.strerror}") from None
