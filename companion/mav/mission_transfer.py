"""The MAVLink mission protocol (mavlink.io "Mission Protocol"), both ways, and the .plan it makes.

Download (:func:`pull`): MISSION_REQUEST_LIST -> MISSION_COUNT, then for each item
MISSION_REQUEST_INT -> MISSION_ITEM_INT, then MISSION_ACK (accepted). Upload (:func:`push`, what
a ground station does; the tests' second client): MISSION_COUNT, then the vehicle asks for each
item (MISSION_REQUEST_INT, or the older MISSION_REQUEST) and ends with MISSION_ACK.

Every request is sent again after ``timeout`` seconds without its answer, ``retries`` times; an
item that never comes, an item out of order, or a MISSION_ACK error from the vehicle mid-way ends
the transfer: a partial mission is never returned (:class:`TransferError`, one line). The
message builders are pymavlink's (``mav.mission_request_list_send`` and the rest) and the list
is pymavlink's own :class:`pymavlink.mavwp.MAVWPLoader` (it numbers ``seq``).

:func:`to_plan` writes the items as a QGroundControl ``.plan`` (the JSON that
:mod:`companion.mission.plan_import` reads): item 0 becomes ``plannedHomePosition`` when the
autopilot keeps home there (ArduPilot: ``AutopilotProfile.mission_home_item``); latitudes and
longitudes are the items' own 1e-7 degree integers divided by 1e7, so a pulled .plan gives the
same items back (:func:`plan_items`).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

os.environ["MAVLINK20"] = "1"   # before pymavlink.mavutil is imported: MAVLink 2 frames
os.environ.setdefault("MAVLINK_DIALECT", "ardupilotmega")
from pymavlink import mavutil, mavwp  # noqa: E402

mavlink = mavutil.mavlink
MISSION = mavlink.MAV_MISSION_TYPE_MISSION
GLOBAL_FRAMES = frozenset({0, 3, 5, 6, 10, 11})   # x / y are latitude / longitude (1e-7 deg)
NAV_WAYPOINT = 16


class TransferError(Exception):
    """The transfer failed; ``str(err)`` is one line. ``started``: the vehicle had answered
    (a broken transfer, a fault) rather than never answering (a user's wrong link or id)."""

    def __init__(self, message: str, started: bool):
        super().__init__(message)
        self.started = started


@dataclass(frozen=True)
class TransferConfig:
    timeout: float = 1.5     # wall s to wait for each answer
    retries: int = 5         # times a request is sent again before giving up


DEFAULT = TransferConfig()


def _wait(master: Any, kinds: tuple[str, ...], sysid: int, compid: int,
          timeout: float) -> Any | None:
    """The next message of ``kinds`` from (sysid, compid) within ``timeout`` s, else None."""
    deadline = time.monotonic() + timeout
    while (left := deadline - time.monotonic()) > 0:
        msg = master.recv_match(type=list(kinds), blocking=True, timeout=min(left, 0.1))
        if msg is not None and msg.get_srcSystem() == sysid and msg.get_srcComponent() == compid:
            if getattr(msg, "mission_type", MISSION) == MISSION:
                return msg
    return None


def _ack_error(msg: Any) -> str:
    names = mavlink.enums["MAV_MISSION_RESULT"]
    name = names[msg.type].name if msg.type in names else str(msg.type)
    return f"MISSION_ACK {name}"


def pull(master: Any, sysid: int, compid: int, config: TransferConfig = DEFAULT,
         log: Callable[[str], None] = lambda text: None) -> mavwp.MAVWPLoader:
    """Read the vehicle's mission: every MISSION_ITEM_INT, in order (raises TransferError)."""
    mav, c = master.mav, config
    count_msg = None
    for _ in range(c.retries + 1):
        mav.mission_request_list_send(sysid, compid, MISSION)
        count_msg = _wait(master, ("MISSION_COUNT",), sysid, compid, c.timeout)
        if count_msg is not None:
            break
    if count_msg is None:
        raise TransferError(f"no MISSION_COUNT from system {sysid} component {compid} after "
                            f"{c.retries + 1} MISSION_REQUEST_LIST ({c.timeout:g} s each)",
                            started=False)
    count = int(count_msg.count)
    log(f"the vehicle holds {count} mission items")
    items = mavwp.MAVWPLoader(target_system=sysid, target_component=compid)
    for seq in range(count):
        item = None
        for attempt in range(c.retries + 1):
            if attempt:
                log(f"no MISSION_ITEM_INT {seq} within {c.timeout:g} s: asking again")
            mav.mission_request_int_send(sysid, compid, seq, MISSION)
            while True:
                msg = _wait(master, ("MISSION_ITEM_INT", "MISSION_ACK"), sysid, compid,
                            c.timeout)
                if msg is None or msg.get_type() == "MISSION_ACK" or msg.seq == seq:
                    break      # an older duplicate of an earlier item: keep waiting
            if msg is not None and msg.get_type() == "MISSION_ACK":
                if msg.type != mavlink.MAV_MISSION_ACCEPTED:
                    raise TransferError(f"the vehicle ended the transfer at item {seq} of "
                                        f"{count} ({_ack_error(msg)}): nothing written",
                                        started=True)
                continue
            if msg is not None:
                item = msg
                break
        if item is None:
            mav.mission_ack_send(sysid, compid, mavlink.MAV_MISSION_OPERATION_CANCELLED,
                                 MISSION)
            raise TransferError(f"partial mission transfer refused: item {seq} of {count} "
                                f"never came ({c.retries + 1} requests, {c.timeout:g} s each); "
                                "nothing written", started=True)
        items.add(item)
    mav.mission_ack_send(sysid, compid, mavlink.MAV_MISSION_ACCEPTED, MISSION)
    return items


def push(master: Any, sysid: int, compid: int, items: list[Any],
         config: TransferConfig = DEFAULT) -> None:
    """Upload ``items`` (MISSION_ITEM_INT messages, seq 0..n-1) as a ground station does."""
    mav, c = master.mav, config
    done: set[int] = set()
    for _ in range(c.retries + 1):
        mav.mission_count_send(sysid, compid, len(items), MISSION)
        while True:
            msg = _wait(master, ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"),
                        sysid, compid, c.timeout)
            if msg is None:
                break
            if msg.get_type() == "MISSION_ACK":
                if msg.type == mavlink.MAV_MISSION_ACCEPTED and len(done) == len(items):
                    return
                raise TransferError(f"upload refused by system {sysid}: {_ack_error(msg)}",
                                    started=True)
            seq = int(msg.seq)
            if not 0 <= seq < len(items):
                raise TransferError(f"the vehicle asked for item {seq} of {len(items)}",
                                    started=True)
            it = items[seq]
            mav.mission_item_int_send(sysid, compid, seq, it.frame, it.command, it.current,
                                      it.autocontinue, it.param1, it.param2, it.param3,
                                      it.param4, it.x, it.y, it.z, MISSION)
            done.add(seq)
        if done:
            break          # the vehicle started asking, then went quiet: do not start over
    raise TransferError(f"mission upload to system {sysid} did not complete "
                        f"({len(done)} of {len(items)} items asked for)", started=bool(done))


def item(seq: int, command: int, frame: int, params: tuple[float, float, float, float],
         x: int, y: int, z: float, autocontinue: int = 1) -> Any:
    """A MISSION_ITEM_INT message object (pymavlink's class), not sent."""
    return mavlink.MAVLink_mission_item_int_message(
        0, 0, seq, frame, command, 0, autocontinue, *params, x, y, z, MISSION)


def waypoint(seq: int, lat: float, lon: float, alt: float = 0.0) -> Any:
    """A NAV_WAYPOINT item at (lat, lon) in MAV_FRAME_GLOBAL_RELATIVE_ALT (3)."""
    return item(seq, NAV_WAYPOINT, 3, (0.0, 0.0, 0.0, 0.0), int(round(lat * 1e7)),
                int(round(lon * 1e7)), alt)


# --- .plan ------------------------------------------------------------------------------------

def _number(value: float) -> float | None:
    return None if not math.isfinite(value) else float(value)   # QGC writes null for NaN


def to_plan(items: mavwp.MAVWPLoader, home_item: bool, vehicle_type: int = 10,
            firmware_type: int = 3) -> dict[str, Any]:
    """A QGroundControl .plan (JSON object) holding ``items`` (see the module docstring)."""
    rows = [items.wp(i) for i in range(items.count())]
    home = [0.0, 0.0, 0.0]
    if home_item and rows:
        h = rows.pop(0)
        home = [h.x / 1e7, h.y / 1e7, float(h.z)]
    plan_items = []
    for n, w in enumerate(rows, start=1):
        if w.frame in GLOBAL_FRAMES:
            x, y = w.x / 1e7, w.y / 1e7
        else:
            x, y = float(w.x), float(w.y)
        plan_items.append({
            "type": "SimpleItem", "command": int(w.command), "frame": int(w.frame),
            "params": [_number(w.param1), _number(w.param2), _number(w.param3),
                       _number(w.param4), x, y, float(w.z)],
            "autoContinue": bool(w.autocontinue), "doJumpId": n})
    return {"fileType": "Plan", "version": 1, "groundStation": "pzc-rover companion",
            "mission": {"version": 2, "firmwareType": firmware_type,
                        "vehicleType": vehicle_type, "cruiseSpeed": None, "hoverSpeed": None,
                        "plannedHomePosition": home, "items": plan_items},
            "geoFence": {"version": 2, "circles": [], "polygons": []},
            "rallyPoints": {"version": 2, "points": []}}


def plan_items(plan: dict[str, Any], home_item: bool) -> list[Any]:
    """The MISSION_ITEM_INTs a .plan stands for (home first when ``home_item``): the inverse
    of :func:`to_plan` (a GCS's upload)."""
    mission = plan["mission"]
    out = []
    if home_item:
        lat, lon, alt = (list(mission.get("plannedHomePosition") or [0, 0, 0]) + [0.0])[:3]
        out.append(item(0, NAV_WAYPOINT, 0, (0.0, 0.0, 0.0, 0.0), int(round(lat * 1e7)),
                        int(round(lon * 1e7)), float(alt)))
    for row in mission["items"]:
        p = [math.nan if v is None else float(v) for v in row["params"]]
        frame = int(row["frame"])
        scale = 1e7 if frame in GLOBAL_FRAMES else 1.0
        out.append(item(len(out), int(row["command"]), frame, (p[0], p[1], p[2], p[3]),
                        int(round(p[4] * scale)), int(round(p[5] * scale)), p[6],
                        int(row.get("autoContinue", True))))
    return out


def same_items(a: list[Any], b: list[Any]) -> list[str]:
    """Where two item lists differ (empty: identical in command, frame, params, position)."""
    out = [] if len(a) == len(b) else [f"{len(a)} items against {len(b)}"]
    for i, (p, q) in enumerate(zip(a, b, strict=False)):
        for field in ("command", "frame", "param1", "param2", "param3", "param4", "x", "y", "z",
                      "autocontinue"):
            u, v = getattr(p, field), getattr(q, field)
            both_nan = isinstance(u, float) and isinstance(v, float) and math.isnan(u) and \
                math.isnan(v)
            if not both_nan and not math.isclose(float(u), float(v), rel_tol=0, abs_tol=1e-4):
                out.append(f"item {i}: {field} {u!r} != {v!r}")
    return out
