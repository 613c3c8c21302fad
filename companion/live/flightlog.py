"""Flight logs that survive a crash: a MAVLink .tlog of all traffic and a CSV of the control loop.

* ``.tlog``: pymavlink's telemetry-log format (what MAVProxy, MAVExplorer and ``mavlogdump.py``
  read): each frame is an 8-byte big-endian timestamp (wall-clock microseconds, low two bits
  clear) followed by the raw MAVLink frame as it crossed the wire, signature included. Incoming
  frames are taken from pymavlink's message hooks (every frame that parsed; garbage and refused
  signatures excluded, as pymavlink's own ``logfile`` does), outgoing ones from the send callback
  of pymavlink's ``MAVLink`` object, so both directions are in one file in the order they
  happened. Reading is pymavlink's too (``mavutil.mavlink_connection("x.tlog")``).
* ``.csv``: one row per tracking cycle (:class:`companion.live.events.LoopRecord`) plus one row per
  life-cycle event (``event`` column set, the numeric columns empty), except that a failsafe
  that stopped the rover carries the zero setpoint it sent (``ux``, ``uy``, ``speed_cmd``,
  ``yaw_rate_cmd`` = 0): the log says what the vehicle was last asked, so an identification
  from it does not hold the tracker's last setpoint through the stop.

Crash safety: both files are buffered (a write per frame would cost a system call in the loop)
and flushed to the operating system

* on a write when the last flush is ``FLUSH_EVERY`` or more ago (a busy loop), and
* when the loop is about to sleep (:meth:`Flushing.idle`, called from ``Link.wait``) and the
  last flush is ``IDLE_FLUSH`` or more ago; the loop never sleeps longer than 50 ms, so

data written is in the kernel within about max(FLUSH_EVERY, IDLE_FLUSH + 50 ms) = 70 ms, and a
``kill -9`` of the companion loses at most that: the page cache belongs to the kernel, not the
process. Status events are flushed at once. ``close`` also fsyncs (power loss is another matter:
fsync per flush would cost milliseconds on an SD card).
"""

from __future__ import annotations

import dataclasses
import os
import struct
import time
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, BinaryIO

from ..errors import UserError
from .events import LoopRecord, StatusEvent

FLUSH_EVERY = 0.05     # wall s: a busy writer flushes at least this often
IDLE_FLUSH = 0.02      # wall s: before sleeping, flush if the last flush is this old
BUFFER = 1 << 16       # bytes: 50 ms of 1 kHz traffic fits, so a flush is one write()
DEFAULT_DIR = "logs"

_stamp = struct.Struct(">Q").pack
CSV_FIELDS = [f.name for f in dataclasses.fields(LoopRecord)] + ["event"]
# the command cells of an event row that sent the zero setpoint (see the module docstring)
STOP_FIELDS = ("ux", "uy", "speed_cmd", "yaw_rate_cmd")
# Format of a loop row: times to the microsecond, positions to 0.1 mm, angles to 1 urad.
_ROW = ("%.6f,%.6f,%.4f,%.4f,%.6f,%.4f,%.4f,%.6f,%.4f,%.4f,%.4f,%.6f,"
        "%.5f,%.5f,%.5f,%.6f,%s,%d,%s,\n")


class Flushing:
    """A binary file written as it goes, flushed by the policy in the module docstring."""

    def __init__(self, f: BinaryIO, clock: Callable[[], float] = time.monotonic):
        self.f = f
        self.clock = clock
        self.path = getattr(f, "name", "")
        self._last = clock()
        self._dirty = False
        self.closed = False

    def write(self, data: bytes) -> None:
        if self.closed:
            return
        self.f.write(data)
        self._dirty = True
        if self.clock() - self._last >= FLUSH_EVERY:
            self.flush()

    def tell(self) -> int:
        """Bytes written so far (the MCAP writer indexes by offset)."""
        return self.f.tell()

    def idle(self) -> None:
        if self._dirty and self.clock() - self._last >= IDLE_FLUSH:
            self.flush()

    def flush(self) -> None:
        if self.closed:
            return
        self.f.flush()
        self._dirty = False
        self._last = self.clock()

    def close(self) -> None:
        if self.closed:
            return
        self.flush()
        try:
            os.fsync(self.f.fileno())
        except OSError:
            pass
        self.f.close()
        self.closed = True


class Tlog(Flushing):
    """The .tlog of one pymavlink connection, both directions (:meth:`attach`)."""

    def attach(self, conn: Any) -> None:
        # Every parsed incoming message passes pymavlink's message hooks (mavfile.post_message;
        # conn.logfile would miss UDP, whose recv_msg does not log); every sent one goes through
        # MAVLink.send, which calls the send callback with the packed message.
        conn.message_hooks.append(self.received)
        conn.mav.set_send_callback(self.sent)

    def received(self, conn: Any, msg: Any) -> None:
        if msg.get_type() != "BAD_DATA":    # garbage, refused signatures: as pymavlink does
            self.write(_stamp(int(time.time() * 1.0e6) & ~3) + msg.get_msgbuf())

    def sent(self, msg: Any) -> None:
        self.write(_stamp(int(time.time() * 1.0e6) & ~3) + msg.get_msgbuf())


class CsvLog:
    """The control loop as CSV: a :class:`companion.live.events.Sink`."""

    def __init__(self, path: str | Path, clock: Callable[[], float] = time.monotonic):
        self.out = Flushing(open(path, "wb", buffering=BUFFER), clock)
        self.path = str(path)
        self.failsafe = ""
        self.out.write((",".join(CSV_FIELDS) + "\n").encode())
        self.out.flush()

    def record(self, rec: LoopRecord) -> None:
        self.out.write((_ROW % (
            rec.vehicle_time, rec.mission_time, rec.x, rec.y, rec.yaw, rec.x_hat, rec.y_hat,
            rec.yaw_hat, rec.x_ref, rec.y_ref, rec.err_pos, rec.err_yaw, rec.ux, rec.uy,
            rec.speed_cmd, rec.yaw_rate_cmd, _clean(rec.mode), rec.armed,
            _clean(rec.failsafe or self.failsafe))).encode())

    def status(self, event: StatusEvent) -> None:
        if event.kind == "failsafe":
            self.failsafe = event.reason
        elif event.kind in ("resumed", "tracking"):
            self.failsafe = ""
        vt = "" if event.vehicle_time is None else f"{event.vehicle_time:.6f}"
        cells = [vt] + [""] * (len(CSV_FIELDS) - 3) + [_clean(self.failsafe),
                                                        _clean(f"{event.kind}: {event.reason}")]
        if event.detail.get("stop"):
            for name in STOP_FIELDS:
                cells[CSV_FIELDS.index(name)] = "0"
        self.out.write((",".join(cells) + "\n").encode())
        self.out.flush()

    def idle(self) -> None:
        self.out.idle()

    def close(self) -> None:
        self.out.close()


def _clean(text: str) -> str:
    """A CSV cell without a separator or line break in it (reasons are free text)."""
    return text.replace(",", ";").replace("\n", " ").replace("\r", " ").replace('"', "'")


@dataclasses.dataclass(frozen=True)
class LogPaths:
    tlog: str
    csv: str | None                  # None with --log-format mcap
    mcap: str | None = None          # with --log-format mcap (:mod:`companion.live.mcaplog`)


def new_paths(log_dir: str | None, label: str, log_format: str = "csv") -> LogPaths:
    """Fresh ``<dir>/<UTC time>-<label>.tlog`` and ``.csv`` (or ``.mcap``), never overwriting
    a log."""
    directory = Path(log_dir or DEFAULT_DIR)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"--log-dir {directory}: cannot create it: {exc.strerror}") from None
    if not os.access(directory, os.W_OK):
        raise UserError(f"--log-dir {directory}: not writable")
    stem = datetime.now(UTC).strftime("%Y%m%d-%H%M%S") + f"-{label}"
    for n in range(1000):
        base = directory / (stem if n == 0 else f"{stem}-{n}")
        tlog, loop = base.with_suffix(".tlog"), base.with_suffix("." + log_format)
        if not tlog.exists() and not loop.exists():
            if log_format == "mcap":
                return LogPaths(str(tlog), None, str(loop))
            return LogPaths(str(tlog), str(loop))
    raise UserError(f"--log-dir {directory}: too many logs named {stem}*")


def open_tlog(path: str) -> Tlog:
    try:
        return Tlog(open(path, "wb", buffering=BUFFER))
    except OSError as exc:
        raise UserError(f"cannot write the flight log {path}: {exc.strerror}") from None


def open_csv(path: str) -> CsvLog:
    try:
        return CsvLog(path)
    except OSError as exc:
        raise UserError(f"cannot write the flight log {path}: {exc.strerror}") from None
