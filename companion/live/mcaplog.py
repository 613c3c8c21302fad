"""The flight log as MCAP, in Foxglove's standard schemas: what Foxglove opens without set-up.

``run --log-format mcap`` writes this in place of the CSV (the .tlog stays: it is the raw
traffic), and ``companion log export`` writes the same channels from a CSV or a .tlog
(:mod:`companion.logs.export`). One home for the layout, :class:`McapLog`:

======================  ===================================  ==================================
topic                   schema (encoding)                    what
======================  ===================================  ==================================
``/rover/pose``         ``foxglove.PoseInFrame`` (protobuf)  measured pose, frame ``local_ned``
``/rover/filtered``     ``foxglove.PoseInFrame``             the model-free filter's estimate
``/rover/reference``    ``foxglove.PoseInFrame``             the trajectory at mission time
``/rover/loop``         ``pzc-rover.Loop`` (JSON schema)     every LoopRecord field: errors,
                                                             u_p, the setpoints sent, mode
``/rover/events``       ``foxglove.Log`` (protobuf)          life-cycle events (failsafe: WARNING)
``/mavlink/<TYPE>``     ``mavlink.<TYPE>`` (JSON schema)     export of a .tlog: every message
``/rover/location``     ``foxglove.LocationFix``             export of a .tlog: GLOBAL_POSITION_INT
======================  ===================================  ==================================

Schemas and encodings are the Foxglove SDK's own (``foxglove.messages``: ``get_schema()``,
``encode()``); the file is written by the ``mcap`` library's writer. Poses are in LOCAL_NED
(x north, y east, z down; yaw from north towards east as a rotation about z), so Foxglove's 3D
panel shows the path as seen from below: set its follow frame to ``local_ned``. Log times are
the companion's wall clock (run) or the log's own (export: the .tlog's receive time; a CSV has
none, so its vehicle time counts from the Unix epoch).

Crash safety is the CSV's (:class:`~companion.live.flightlog.Flushing`): the writer does not
chunk (a chunk would sit in memory until full), so every message is in the file buffer as it is
written and in the kernel within 70 ms; a ``kill -9`` leaves a file with no summary or footer,
which Foxglove and ``mcap``'s non-seeking reader read to the last whole message
(:func:`read_counts` does). ``close`` writes the summary (message index, statistics).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import fields
from pathlib import Path
from typing import Any

from ..errors import UserError
from .events import LoopRecord, StatusEvent
from .flightlog import BUFFER, Flushing

FRAME = "local_ned"
PROFILE = "pzc-rover"
INSTALL = "pip install 'pzc-rover[mcap]'"
_LOOP_FIELDS = [f.name for f in fields(LoopRecord)]


def _require() -> tuple[Any, Any]:
    try:
        import foxglove.messages as fm
        from mcap.writer import Writer
    except ImportError as exc:
        raise UserError(f"MCAP logs need the mcap and foxglove-sdk packages ({INSTALL}): "
                        f"{exc}") from None
    return fm, Writer


def loop_schema() -> dict[str, Any]:
    """The JSON schema of ``/rover/loop``: every LoopRecord field, numbers null when not finite."""
    props: dict[str, Any] = {}
    for f in fields(LoopRecord):
        kind = {"str": "string", "bool": "boolean"}.get(str(f.type), "number")
        props[f.name] = {"type": [kind, "null"] if kind == "number" else kind}
    return {"title": "pzc-rover.Loop", "type": "object", "properties": props}


def _finite(v: Any) -> Any:
    return None if isinstance(v, float) and not math.isfinite(v) else v


class McapLog:
    """An MCAP flight log being written: a :class:`~companion.live.events.Sink` for the runner,
    and the writer :mod:`companion.logs.export` feeds with its own times."""

    def __init__(self, path: str | Path, clock: Callable[[], float] = time.monotonic,
                 wall: Callable[[], float] = time.time, metadata: dict[str, str] | None = None):
        fm, Writer = _require()
        self.fm = fm
        self.path = str(path)
        self.wall = wall
        self.out = Flushing(open(path, "wb", buffering=BUFFER), clock)
        # No chunks: each message goes straight to the (flushed) file, so a crash keeps it.
        self.writer = Writer(self.out, use_chunking=False)
        self.writer.start(profile=PROFILE, library="pzc-rover companion")
        if metadata:
            self.writer.add_metadata("pzc-rover", metadata)
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self.counts: dict[str, int] = {}
        self.out.flush()
        self.failsafe = ""

    # --- channels ------------------------------------------------------------------------------
    def _channel(self, topic: str, schema_name: str, encoding: str, data: bytes,
                 message_encoding: str) -> int:
        ch = self._channels.get(topic)
        if ch is None:
            sid = self._schemas.get(schema_name)
            if sid is None:
                sid = self.writer.register_schema(schema_name, encoding, data)
                self._schemas[schema_name] = sid
            ch = self.writer.register_channel(topic, message_encoding, sid)
            self._channels[topic] = ch
        return ch

    def _foxglove(self, topic: str, message: Any, t_ns: int) -> None:
        schema = type(message).get_schema()
        ch = self._channel(topic, schema.name, schema.encoding, bytes(schema.data), "protobuf")
        self._write(ch, topic, message.encode(), t_ns)

    def json(self, topic: str, schema_name: str, schema: dict[str, Any], body: dict[str, Any],
             t_ns: int) -> None:
        """One JSON message on ``topic`` (``schema``: its JSON schema, registered once)."""
        ch = self._channels.get(topic)
        if ch is None:
            ch = self._channel(topic, schema_name, "jsonschema", json.dumps(schema).encode(),
                               "json")
        data = json.dumps(body, separators=(",", ":"), allow_nan=False, default=str).encode()
        self._write(ch, topic, data, t_ns)

    def _write(self, ch: int, topic: str, data: bytes, t_ns: int) -> None:
        if self.out.closed:
            return
        self.writer.add_message(ch, log_time=t_ns, data=data, publish_time=t_ns)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    # --- typed messages ------------------------------------------------------------------------
    def pose(self, topic: str, x: float, y: float, yaw: float | None, t_ns: int) -> None:
        fm = self.fm
        yaw = 0.0 if yaw is None or not math.isfinite(yaw) else yaw
        if not (math.isfinite(x) and math.isfinite(y)):
            return          # no pose to draw (a NaN from the filter): the loop row keeps it
        self._foxglove(topic, fm.PoseInFrame(
            timestamp=_stamp(fm, t_ns), frame_id=FRAME,
            pose=fm.Pose(position=fm.Vector3(x=x, y=y, z=0.0),
                         orientation=fm.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                   w=math.cos(yaw / 2)))), t_ns)

    def trajectory(self, topic: str, xs: Any, ys: Any, t_ns: int) -> None:
        fm = self.fm
        poses = [fm.Pose(position=fm.Vector3(x=float(x), y=float(y), z=0.0),
                         orientation=fm.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))
                 for x, y in zip(xs, ys, strict=True) if math.isfinite(x) and math.isfinite(y)]
        self._foxglove(topic, fm.PosesInFrame(timestamp=_stamp(fm, t_ns), frame_id=FRAME,
                                              poses=poses), t_ns)

    def location(self, lat: float, lon: float, alt: float, t_ns: int) -> None:
        fm = self.fm
        self._foxglove("/rover/location", fm.LocationFix(
            timestamp=_stamp(fm, t_ns), frame_id=FRAME, latitude=lat, longitude=lon,
            altitude=alt), t_ns)

    def event(self, text: str, warning: bool, t_ns: int, name: str = "companion") -> None:
        fm = self.fm
        level = fm.LogLevel.Warning if warning else fm.LogLevel.Info
        self._foxglove("/rover/events", fm.Log(timestamp=_stamp(fm, t_ns), level=level,
                                               message=text, name=name), t_ns)

    def loop(self, rec: LoopRecord, t_ns: int) -> None:
        body = {name: _finite(getattr(rec, name)) for name in _LOOP_FIELDS}
        body["failsafe"] = rec.failsafe or self.failsafe
        self.json("/rover/loop", "pzc-rover.Loop", loop_schema(), body, t_ns)
        self.pose("/rover/pose", rec.x, rec.y, rec.yaw, t_ns)
        self.pose("/rover/filtered", rec.x_hat, rec.y_hat, rec.yaw_hat, t_ns)
        self.pose("/rover/reference", rec.x_ref, rec.y_ref, None, t_ns)

    # --- Sink ----------------------------------------------------------------------------------
    def record(self, rec: LoopRecord) -> None:
        self.loop(rec, int(self.wall() * 1e9))

    def status(self, event: StatusEvent) -> None:
        if event.kind == "failsafe":
            self.failsafe = event.reason
        elif event.kind in ("resumed", "tracking"):
            self.failsafe = ""
        self.event(f"{event.kind}: {event.reason}", event.kind in ("failsafe", "pilot_override"),
                   int(self.wall() * 1e9))
        self.out.flush()

    def idle(self) -> None:
        self.out.idle()

    def close(self) -> None:
        if self.out.closed:
            return
        self.writer.finish()
        self.out.close()


def _stamp(fm: Any, t_ns: int) -> Any:
    return fm.Timestamp(sec=t_ns // 1_000_000_000, nsec=t_ns % 1_000_000_000)


def open_mcap(path: str, metadata: dict[str, str] | None = None) -> McapLog:
    try:
        return McapLog(path, metadata=metadata)
    except OSError as exc:
        raise UserError(f"cannot write the flight log {path}: {exc.strerror}") from None


def read_counts(path: str | Path) -> dict[str, int]:
    """Messages per topic in an MCAP file, read to the end of the data (summary or not)."""
    from mcap.reader import NonSeekingReader
    counts: dict[str, int] = {}
    with open(path, "rb") as f:
        reader = NonSeekingReader(f, validate_crcs=True)
        try:
            for _schema, channel, _message in reader.iter_messages(log_time_order=False):
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
        except Exception:  # noqa: BLE001 - a file cut by a crash ends in a torn record
            pass
    return counts
