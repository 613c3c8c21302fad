"""A flight log (.csv or .tlog) rewritten as MCAP, in the channels of
:mod:`companion.live.mcaplog` (what ``run --log-format mcap`` writes live).

* From the companion's CSV: one ``/rover/loop`` (and ``/rover/pose``, ``/rover/filtered``,
  ``/rover/reference``) per loop row, one ``/rover/events`` per event row, and the whole
  reference as one ``/rover/reference_path`` (``foxglove.PosesInFrame``). The CSV has no wall
  clock: log time is the vehicle time since the Unix epoch.
* From a .tlog (pymavlink reads it): every MAVLink message on ``/mavlink/<TYPE>`` as JSON (its
  fields, as ``msg.to_dict()`` gives them), log time the .tlog's own stamp; and from them
  ``/rover/pose`` (LOCAL_POSITION_NED with the last ATTITUDE of the same vehicle),
  ``/rover/location`` (GLOBAL_POSITION_INT) and ``/rover/events`` (STATUSTEXT).

:func:`export` returns the messages written per topic and what the source held, so a caller
(and the test) can check that nothing was dropped.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from ..errors import UserError
from ..live.events import LoopRecord
from ..live.flightlog import CSV_FIELDS
from ..live.mcaplog import McapLog

# a CSV row's first 16 columns: LoopRecord's numeric fields, in order
_NUMBERS = tuple(f.name for f in fields(LoopRecord))[:16]

_NUMERIC = CSV_FIELDS[:16]
_MAVLINK_SCHEMA = {"type": "object", "description": "a MAVLink message's fields "
                   "(pymavlink's to_dict); mavpackettype names the message"}


@dataclass
class Exported:
    source: str
    out: str
    kind: str                                        # "csv" or "tlog"
    written: dict[str, int] = field(default_factory=dict)   # topic -> messages
    source_counts: dict[str, int] = field(default_factory=dict)  # what the source held
    skipped: int = 0                                 # corrupt rows / frames


def export(log: str, out: str) -> Exported:
    """Write ``out`` (.mcap) from ``log`` (.csv or .tlog); UserError when either is unusable."""
    src = Path(log)
    if not src.is_file():
        raise UserError(f"LOG {log}: no such file")
    suffix = src.suffix.lower()
    if suffix not in (".csv", ".tlog", ".log", ".mav"):
        raise UserError(f"LOG {log}: expected a .csv or .tlog flight log")
    if Path(out).resolve() == src.resolve():
        raise UserError(f"--mcap {out}: would overwrite the log itself")
    try:
        sink = McapLog(out, metadata={"source": str(src)})
    except OSError as exc:
        raise UserError(f"--mcap {out}: cannot write: {exc.strerror}") from None
    result = Exported(str(src), out, "csv" if suffix == ".csv" else "tlog")
    try:
        (_from_csv if suffix == ".csv" else _from_tlog)(src, sink, result)
    except BaseException:
        sink.close()
        Path(out).unlink(missing_ok=True)      # never a half-done file
        raise
    sink.close()
    result.written = dict(sink.counts)
    return result


def _ns(seconds: float) -> int:
    return max(0, int(round(seconds * 1e9)))


def _from_csv(src: Path, sink: McapLog, result: Exported) -> None:
    loops = events = 0
    ref_x: list[float] = []
    ref_y: list[float] = []
    first_ns: int | None = None
    last_ns = 0
    try:
        with open(src, newline="", encoding="utf-8", errors="replace") as f:
            reader = csv.reader(f)
            header = next(reader, None)
            if header is None or header[:len(_NUMERIC)] != _NUMERIC:
                raise UserError(f"LOG {src}: not a companion flight-log CSV")
            width = len(header)
            failsafe_at = header.index("failsafe")
            for row in reader:
                if len(row) != width:
                    result.skipped += 1
                    continue
                if row[-1]:                       # an event row: vehicle time may be empty
                    try:
                        t_ns = _ns(float(row[0])) if row[0] else last_ns
                    except ValueError:
                        result.skipped += 1
                        continue
                    text = row[-1]
                    sink.event(text, text.startswith(("failsafe", "pilot_override")), t_ns)
                    events += 1
                    continue
                try:
                    v = [float(c) for c in row[:16]]
                except ValueError:
                    result.skipped += 1
                    continue
                rec = LoopRecord(**dict(zip(_NUMBERS, v, strict=True)), mode=row[16], armed=row[17] in ("1", "True", "true"),
                                 failsafe=row[failsafe_at])
                last_ns = _ns(rec.vehicle_time)
                first_ns = last_ns if first_ns is None else first_ns
                sink.loop(rec, last_ns)
                ref_x.append(rec.x_ref)
                ref_y.append(rec.y_ref)
                loops += 1
    except OSError as exc:
        raise UserError(f"LOG {src}: cannot read: {exc.strerror}") from None
    except csv.Error as exc:
        raise UserError(f"LOG {src}: not a CSV file: {exc}") from None
    if ref_x:
        sink.trajectory("/rover/reference_path", ref_x, ref_y, first_ns or 0)
    result.source_counts = {"loop rows": loops, "event rows": events}


def _from_tlog(src: Path, sink: McapLog, result: Exported) -> None:
    from ..live.link import mavutil  # MAVLink 2 set up before pymavlink is imported
    try:
        conn = mavutil.mavlink_connection(str(src), dialect="ardupilotmega")
    except Exception as exc:  # noqa: BLE001 - pymavlink raises anything on a bad file
        raise UserError(f"LOG {src}: cannot open as a tlog ({type(exc).__name__}: {exc})") \
            from None
    att: dict[tuple[int, int], float] = {}
    counts: dict[str, int] = {}
    try:
        while True:
            try:
                msg = conn.recv_msg()
            except Exception:  # noqa: BLE001 - a torn last frame
                result.skipped += 1
                break
            if msg is None:
                break
            kind = msg.get_type()
            if kind == "BAD_DATA":
                result.skipped += 1
                continue
            t_ns = _ns(getattr(msg, "_timestamp", 0.0) or 0.0)
            body = _jsonable(msg.to_dict())
            sink.json(f"/mavlink/{kind}", f"mavlink.{kind}", _MAVLINK_SCHEMA, body, t_ns)
            counts[kind] = counts.get(kind, 0) + 1
            src_id = (msg.get_srcSystem(), msg.get_srcComponent())
            if kind == "ATTITUDE":
                att[src_id] = msg.yaw
            elif kind == "LOCAL_POSITION_NED" and src_id in att:
                sink.pose("/rover/pose", msg.x, msg.y, att[src_id], t_ns)
            elif kind == "GLOBAL_POSITION_INT":
                sink.location(msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3, t_ns)
            elif kind == "STATUSTEXT":
                sink.event(str(msg.text), msg.severity <= 4, t_ns,
                           name=f"vehicle {msg.get_srcSystem()}")
    finally:
        conn.close()
    if not counts:
        raise UserError(f"LOG {src}: no MAVLink messages in it")
    result.source_counts = counts


def _jsonable(obj: Any) -> Any:
    """pymavlink's dict as JSON: bytes as text, non-finite floats as null."""
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, bytes):
        return obj.decode("latin-1")
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
