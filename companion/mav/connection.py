"""Open a pymavlink connection from a connection string, serial devices included, with one-line
errors: shared by the companion and ``sitl_plant``.

A network or file URL (``udpin:``, ``tcp:``, ``udpout:`` ...) goes to
``mavutil.mavlink_connection`` unchanged. A serial device (``/dev/ttyAMA0``, ``/dev/ttyACM0``,
``/dev/serial/by-id/...``, ``COM3``) is pymavlink's ``mavserial`` over pyserial, at the baud rate of
pymavlink's ``DEVICE,BAUD`` form or of ``baud`` (default 115200, pymavlink's default; ArduPilot's
companion ports usually run 921600: SERIALn_BAUD 921). Serial devices are told apart here rather
than by pymavlink because pymavlink takes any string with a colon for a UDP address, and the
kernel's ``/dev/serial/by-path/...-usb-0:1.2:1.0`` names have colons.

The device is locked for this process (pyserial's ``exclusive``: ``flock``), so two programs
reading one UART (each would see half the bytes) is an error rather than a corrupt link. Programs
that take no lock (``cat``, ``screen``) cannot be seen this way. An absent device, a device without
permission, a busy one and a file that is not a terminal each give one line naming the device.
"""

from __future__ import annotations

import errno
import os
import stat
from typing import Any

from ..errors import UserError

DEFAULT_BAUD = 115200   # pymavlink's (mavlink_connection, mavserial); MAVProxy's is 57600
# File names pymavlink reads as logs rather than devices (its own list, and its readers' suffixes).
_LOG_SUFFIXES = (".tlog", ".log", ".bin", ".px4log", ".mavlink", ".raw")


def parse_baud(text: str) -> int:
    """A baud rate: a whole number of bits per second > 0 (ValueError otherwise)."""
    try:
        value = int(text, 10)
    except (TypeError, ValueError):
        raise ValueError(f"not a whole number: {text!r}") from None
    if value <= 0:
        raise ValueError(f"must be > 0, not {value}")
    return value


def serial_target(url: str, baud: int | None = None) -> tuple[str, int] | None:
    """(device, baud) when ``url`` names a serial device, else None (a network URL or a log file).

    ``DEVICE,BAUD`` (pymavlink's form) gives the rate; a ``baud`` that disagrees with it is an
    error. Without either, :data:`DEFAULT_BAUD`.
    """
    device, rate = url, None
    head, comma, tail = url.rpartition(",")
    if comma and head and not os.path.exists(url):
        if not _is_serial(head):
            return None
        device = head
        try:
            rate = parse_baud(tail.strip())
        except ValueError as exc:
            raise UserError(f"bad baud rate in {url!r}: {exc}") from None
    elif not _is_serial(device):
        return None
    if rate is not None and baud is not None and rate != baud:
        raise UserError(f"two baud rates for {device}: {rate} in {url!r} and {baud} (--baud); "
                        "give one")
    return device, rate or baud or DEFAULT_BAUD


def _is_serial(device: str) -> bool:
    try:
        mode = os.stat(device).st_mode
    except OSError:
        # Absent (or unreadable): serial when pymavlink would open it as one (no colon, not a log
        # file's name), or when it is under /dev.
        return device.startswith("/dev/") or (
            ":" not in device and not device.lower().endswith(_LOG_SUFFIXES))
    return stat.S_ISCHR(mode)


def open_connection(url: str, baud: int | None = None, **kwargs: Any) -> Any:
    """``mavutil.mavlink_connection(url, **kwargs)``, or pymavlink's ``mavserial`` for a serial
    device (see the module docstring). ``baud`` only applies to serial devices. Raises
    :class:`UserError` with one line when the connection cannot be opened."""
    os.environ["MAVLINK20"] = "1"   # before pymavlink.mavutil is first imported: MAVLink 2
    from pymavlink import mavutil
    target = serial_target(url, baud)
    if target is None:
        try:
            return mavutil.mavlink_connection(url, **kwargs)
        except Exception as exc:  # noqa: BLE001  (pymavlink raises anything from ValueError to OSError)
            raise UserError(f"cannot open {url!r}: {exc}") from None
    return _open_serial(mavutil, *target, **kwargs)


def _open_serial(mavutil: Any, device: str, baud: int, dialect: str | None = None,
                 source_system: int = 255, source_component: int = 0) -> Any:
    try:
        import serial
    except ImportError:
        raise UserError(f"cannot open serial device {device}: pyserial is not installed "
                        "(pip install pyserial)") from None
    if dialect is not None:
        mavutil.set_dialect(dialect)
    try:
        conn = mavutil.mavserial(device, baud=baud, source_system=source_system,
                                 source_component=source_component)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise UserError(f"cannot open serial device {device}: {_why(device, exc)}") from None
    # pymavlink reads this flag only to print "Device X is dead" once, on stdout (where a
    # command's JSON result goes), when a write fails; the companion's failsafes report a dead
    # link on stderr.
    conn.portdead = True
    try:
        conn.port.exclusive = True   # pyserial's flock(LOCK_EX | LOCK_NB) on the open port
    except (serial.SerialException, OSError) as exc:
        conn.close()
        raise UserError(f"cannot open serial device {device}: {_why(device, exc)}") from None
    return conn


def _why(device: str, exc: BaseException) -> str:
    code = getattr(exc, "errno", None)
    if code == errno.ENOENT:
        return "no such device (is it plugged in, and the UART enabled?)"
    if code in (errno.EACCES, errno.EPERM):
        return ("permission denied (add the user to the device's group, usually dialout: "
                f"ls -l {device})")
    if code in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK):
        return f"busy: another program has it open (fuser -v {device} shows which)"
    if code == errno.ENXIO:
        return "no such device (the port exists but nothing answers: unplugged?)"
    if isinstance(exc, ValueError):
        return f"bad baud rate or setting: {exc}"
    text = str(exc)
    if "Inappropriate ioctl" in text or code == errno.ENOTTY:
        return "not a serial device (not a terminal)"
    return text.splitlines()[0] if text else type(exc).__name__
