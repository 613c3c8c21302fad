"""The payloads on the keys of :mod:`companion.bus.keys`: built from the loop's records, encoded,
decoded (a contract: the JSON fields are what every reader relies on).

Payloads are UTF-8 JSON objects (readable with any tool, ~600 bytes, ~10 us to encode; a binary
encoding would save bytes the loop does not miss at 20-1000 Hz). Each carries a ``schema`` field
``"pzc-rover/<kind>/<major>"``: a reader must refuse a major it does not know and ignore fields it
does not know (fields are only ever added within a major). Units: metres, radians, seconds;
positions are LOCAL_NED (x north, y east), yaw from north towards east.

``pzc-rover/state/1``::

    {"schema": "pzc-rover/state/1", "vehicle_id": "rover1",
     "seq": 42,                 # tracking-cycle count since the companion started (steps by
                                # N when decimated: a jump larger than "every" is a lost sample)
     "every": 1,                # the decimation N
     "sent_at": 1732368000.123, # companion wall clock (Unix s) at publication
     "vehicle_time": 12.345,    # vehicle clock (time_boot_ms / 1000)
     "mission_time": 3.21,      # mission clock (stands still while paused)
     "pose":      {"x": .., "y": .., "yaw": ..},   # measured (LOCAL_POSITION_NED, ATTITUDE)
     "filtered":  {"x": .., "y": .., "yaw": ..},   # the model-free filter's estimate
     "reference": {"x": .., "y": ..},              # the trajectory at mission_time
     "error":     {"position": .., "yaw": ..},     # |p_ref - p| and yaw of u_p minus yaw_hat
     "setpoint":  {"speed": .., "yaw_rate": .., "ux": .., "uy": ..},   # what was sent
     "mode": "GUIDED", "armed": true}

``pzc-rover/status/1``::

    {"schema": "pzc-rover/status/1", "vehicle_id": "rover1", "seq": 3, "sent_at": ..,
     "kind": "connected" | "tracking" | "paused" | "resumed" | "mission_loaded" | "mission_done"
             | "failsafe" | "pilot_override" | "stopped" | "gnss",
     "reason": "free text", "vehicle_time": 12.3 | null, "detail": {..}}

A kind in :data:`NOTICES` says something (the receiver's class, a drop it acted on) without
changing the vehicle's life-cycle state: a reader keeps the state the last other kind gave.

``pzc-rover/control-reply/1``: ``{"ok", "verb", "message"}`` (``status`` adds ``"status"``), see
:mod:`companion.bus.control`.
"""

from __future__ import annotations

import json
import math
from typing import Any

from ..live.events import LoopRecord, StatusEvent

STATE_SCHEMA = "pzc-rover/state/1"
STATUS_SCHEMA = "pzc-rover/status/1"
REPLY_SCHEMA = "pzc-rover/control-reply/1"


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


def state_payload(vehicle_id: str, seq: int, every: int, rec: LoopRecord,
                  sent_at: float) -> dict[str, Any]:
    return {
        "schema": STATE_SCHEMA, "vehicle_id": vehicle_id, "seq": seq, "every": every,
        "sent_at": sent_at, "vehicle_time": rec.vehicle_time, "mission_time": rec.mission_time,
        "pose": {"x": rec.x, "y": rec.y, "yaw": rec.yaw},
        "filtered": {"x": rec.x_hat, "y": rec.y_hat, "yaw": rec.yaw_hat},
        "reference": {"x": rec.x_ref, "y": rec.y_ref},
        "error": {"position": rec.err_pos, "yaw": rec.err_yaw},
        "setpoint": {"speed": rec.speed_cmd, "yaw_rate": rec.yaw_rate_cmd,
                     "ux": rec.ux, "uy": rec.uy},
        "mode": rec.mode, "armed": rec.armed,
    }


def status_payload(vehicle_id: str, seq: int, event: StatusEvent,
                   sent_at: float) -> dict[str, Any]:
    return {"schema": STATUS_SCHEMA, "vehicle_id": vehicle_id, "seq": seq, "sent_at": sent_at,
            "kind": event.kind, "reason": event.reason, "vehicle_time": event.vehicle_time,
            "detail": event.detail}


def reply_payload(ok: bool, verb: str, message: str,
                  extra: dict[str, Any] | None = None) -> dict[str, Any]:
    return {"schema": REPLY_SCHEMA, "ok": ok, "verb": verb, "message": message, **(extra or {})}


def encode(payload: dict[str, Any]) -> bytes:
    try:
        return json.dumps(payload, separators=(",", ":"), allow_nan=False).encode()
    except ValueError:
        # A NaN from the filter must not make the JSON unreadable: null it (rare path).
        return json.dumps(_sanitize(payload), separators=(",", ":")).encode()


def _sanitize(obj: Any) -> Any:
    if isinstance(obj, float):
        return _finite(obj)
    if isinstance(obj, dict):
        return {k: _sanitize(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_sanitize(v) for v in obj]
    return obj


NOTICES = frozenset({"gnss"})     # status kinds that leave the life-cycle state as it was


def decode(data: bytes, kind: str | None = None) -> dict[str, Any]:
    """Parse a payload; ValueError if it is not one of ours (or not of ``kind``, major 1)."""
    obj = json.loads(data)
    if not isinstance(obj, dict) or not isinstance(obj.get("schema"), str):
        raise ValueError("no schema field")
    parts = obj["schema"].split("/")
    if len(parts) != 3 or parts[0] != "pzc-rover" or parts[2] != "1":
        raise ValueError(f"unknown schema {obj['schema']!r}")
    if kind is not None and parts[1] != kind:
        raise ValueError(f"expected a {kind} payload, got {obj['schema']!r}")
    return obj
