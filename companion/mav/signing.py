"""MAVLink 2 signing keys: load a 32-byte secret safely, and turn signing on for a pymavlink link.

Shared by the companion and the plant (``sitl_plant`` already builds on :mod:`companion`; this
module imports nothing but the standard library and :mod:`companion.errors`, so the plant does
not pull in the control loop).

A key file holds the 32-byte secret either raw (exactly 32 bytes) or as 64 hexadecimal digits
(whitespace around them ignored), the two forms people produce with ``head -c 32 /dev/urandom``
and ``openssl rand -hex 32``. A key file that anyone but its owner may read or write is
refused: a stranger who can read the key can steer the rover.

Signing itself is pymavlink's (``mavfile.setup_signing``): outgoing frames are signed, and
incoming frames that are unsigned, signed with another key or replayed come back as
``BAD_DATA('Invalid signature')``. Every refusal is counted in ``mav.signing.reject_count``
because an ``allow_unsigned_callback`` is always installed (pymavlink only counts with one).
"""

from __future__ import annotations

from typing import Any

from ..errors import UserError
from ..secretfile import read_private

KEY_BYTES = 32
# Sent unsigned by SiK radios themselves (ArduPilot accepts it unsigned for the same reason);
# it carries link quality, never a command or a pose.
UNSIGNED_OK = frozenset({109})   # RADIO_STATUS


def load_key(path: str, flag: str = "--signing-key") -> bytes:
    """The 32-byte secret in ``path``; a one-line UserError naming the flag and file otherwise."""
    data = read_private(path, flag, "key", 4 * KEY_BYTES + 1)
    if len(data) == KEY_BYTES:
        return data
    text = data.strip()
    if len(text) == 2 * KEY_BYTES:
        try:
            return bytes.fromhex(text.decode("ascii"))
        except (UnicodeDecodeError, ValueError):
            pass
    raise UserError(f"{flag} {path}: a key is exactly {KEY_BYTES} bytes or {2 * KEY_BYTES} hex "
                    f"digits, this file has {len(data)} bytes")


def allow_unsigned(mav: Any, msg_id: int) -> bool:
    """pymavlink's allow_unsigned_callback: only RADIO_STATUS may come unsigned."""
    return msg_id in UNSIGNED_OK


def enable(conn: Any, key: bytes) -> None:
    """Sign everything ``conn`` (a pymavlink mavfile) sends; refuse and count unsigned input."""
    conn.setup_signing(key, sign_outgoing=True, allow_unsigned_callback=allow_unsigned)


def rejected(conn: Any) -> int:
    """Incoming frames refused for their signature (unsigned, wrong key, replayed)."""
    return int(conn.mav.signing.reject_count)
