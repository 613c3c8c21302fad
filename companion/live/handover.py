"""Hand-over inside AUTO (``companion run --handover``): the autopilot flies its own mission and
hands the companion the segments marked for it.

ArduPilot Rover's ``MAV_CMD_NAV_GUIDED_ENABLE`` (92) as a mission item, param1 > 0, puts AUTO
into its guided sub-mode (``Rover/mode_auto.cpp``: ``do_nav_guided_enable`` ->
``start_guided``): the heartbeat still says AUTO, MISSION_CURRENT gives the item's sequence
number, and SET_POSITION_TARGET_LOCAL_NED from the companion is obeyed. The item completes
(``verify_nav_guided_enable``) when the vehicle is within WP_RADIUS of the item's location, if
it has one, or when a limit of a ``MAV_CMD_DO_GUIDED_LIMITS`` (222) is breached; AUTO then goes
on with the next item, and MISSION_SET_CURRENT moves it on at once.

A segment (docs/ground-station.md) is what lies between an enable (92, param1 1, no location:
latitude and longitude 0) and the next disable (92, param1 0): its NAV_WAYPOINT items, at the
speed of the last DO_CHANGE_SPEED before them (else the mission's). When AUTO reaches the
enable item, the companion tracks a path from the rover's pose at that moment through those
waypoints (corners rounded as any .plan's), and at its end hands back: one zero setpoint, then
MISSION_SET_CURRENT to the disable item (sent again each second until MISSION_CURRENT shows
AUTO has moved on), after which AUTO runs the disable (it completes at once) and the items
after it, and the companion waits for the next enable. If AUTO leaves the enable item by
itself (a DO_GUIDED_LIMITS timeout, a location reached), the companion stops sending at once
and waits again. The run ends (exit 0) when the vehicle reports the last item reached; a pilot
or GCS mode change out of AUTO, or any failsafe, ends it as any run ends.

:func:`segments` is pure (items in, segments out); :class:`Handover` is the loop's side: it
reads MISSION_CURRENT / MISSION_ITEM_REACHED and asks the runner to begin or end a segment.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..errors import UserError
from ..mission import geo

NAV_WAYPOINT, NAV_GUIDED_ENABLE, DO_CHANGE_SPEED = 16, 92, 178
GLOBAL_FRAMES = frozenset({0, 3, 5, 6, 10, 11})
RETRY_S = 1.0            # wall s between MISSION_SET_CURRENT tries
DEFAULT_SPEED = 2.0      # m/s: ArduPilot Rover's WP_SPEED default, when the mission gives none


@dataclass(frozen=True)
class Segment:
    enable_seq: int                               # the NAV_GUIDED_ENABLE 1 item
    resume_seq: int                               # the NAV_GUIDED_ENABLE 0 item: AUTO goes on there
    points: tuple[tuple[float, float], ...]       # (lat, lon) of its waypoints, in order
    speed: float                                  # m/s


def segments(items: list[Any]) -> dict[int, Segment]:
    """The hand-over segments of a mission (MISSION_ITEM_INT-like objects, seq order), by the
    enable item's sequence number. A malformed one is a UserError naming the item."""
    out: dict[int, Segment] = {}
    speed = DEFAULT_SPEED
    open_at: int | None = None
    points: list[tuple[float, float]] = []
    seg_speed = speed
    for seq, it in enumerate(items):
        cmd = int(it.command)
        if cmd == DO_CHANGE_SPEED and math.isfinite(it.param2) and it.param2 > 0:
            speed = float(it.param2)
            if open_at is not None and not points:
                seg_speed = speed
        elif cmd == NAV_GUIDED_ENABLE and it.param1 > 0:
            if open_at is not None:
                raise UserError(f"mission item {seq}: NAV_GUIDED_ENABLE 1 inside the hand-over "
                                f"opened at item {open_at}: close it with NAV_GUIDED_ENABLE 0")
            if it.x != 0 or it.y != 0:
                raise UserError(f"mission item {seq}: NAV_GUIDED_ENABLE with a location: AUTO "
                                "would end the hand-over on reaching it; give it latitude and "
                                "longitude 0 (the segment is the waypoints up to the disable)")
            open_at, points, seg_speed = seq, [], speed
        elif cmd == NAV_GUIDED_ENABLE:
            if open_at is None:
                continue        # a disable outside a segment: AUTO passes it at once
            if not points:
                raise UserError(f"mission items {open_at}..{seq}: a hand-over without "
                                "NAV_WAYPOINT items: nothing for the companion to track")
            out[open_at] = Segment(open_at, seq, tuple(points), seg_speed)
            open_at = None
        elif cmd == NAV_WAYPOINT and open_at is not None:
            if int(it.frame) not in GLOBAL_FRAMES:
                raise UserError(f"mission item {seq}: NAV_WAYPOINT in MAV_FRAME {it.frame}: "
                                "only global (lat/lon) frames are supported")
            points.append((it.x / 1e7, it.y / 1e7))
    if open_at is not None:
        raise UserError(f"mission item {open_at}: NAV_GUIDED_ENABLE 1 is never closed by a "
                        "NAV_GUIDED_ENABLE 0: the companion would not know where to hand back")
    return out


@dataclass
class SegmentResult:
    enable_seq: int
    resume_seq: int
    duration: float
    steady_rms: float
    f_cost: float
    ended: str                 # "handed back" or why AUTO took it back

    def as_dict(self) -> dict[str, Any]:
        return {"items": [self.enable_seq, self.resume_seq], "duration": self.duration,
                "steady_rms": self.steady_rms, "f_cost": self.f_cost, "ended": self.ended}


@dataclass
class Handover:
    """The loop's side of the hand-overs (see the module docstring)."""

    plan: dict[int, Segment]
    last_seq: int                              # the mission's last item
    make_mission: Callable[[Segment, tuple[float, float, float]], Any]
    send_set_current: Callable[[int], None]
    log: Callable[[str], None]
    current: int = -1                          # MISSION_CURRENT as last heard
    active: Segment | None = None              # tracking it now
    handing_back: Segment | None = None        # MISSION_SET_CURRENT sent, AUTO not moved yet
    next_try: float = 0.0
    done: set[int] = field(default_factory=set)
    results: list[SegmentResult] = field(default_factory=list)
    complete: bool = False                     # the vehicle reported the last item reached

    @property
    def quiet(self) -> bool:
        """True while the vehicle drives itself: the companion sends nothing at all."""
        return self.active is None

    def on_message(self, msg: Any, runner: Any) -> None:
        kind = msg.get_type()
        if kind == "MISSION_ITEM_REACHED":
            if int(msg.seq) >= self.last_seq:
                self.complete = True
                runner.handover_finished(f"AUTO reached the last mission item ({msg.seq})")
            return
        seq = int(msg.seq)                     # MISSION_CURRENT
        changed, self.current = seq != self.current, seq
        now = time.monotonic()
        back = self.handing_back
        if back is not None:
            if seq != back.enable_seq:
                self.log(f"AUTO resumed at mission item {seq}")
                self.handing_back = None
            elif now >= self.next_try:
                self.send_set_current(back.resume_seq)
                self.next_try = now + RETRY_S
            return
        active = self.active
        if active is not None and seq != active.enable_seq:
            self.active = None
            runner.handover_ended(f"AUTO moved on to item {seq} by itself", handed_back=False)
            return
        if changed and active is None and seq in self.plan and seq not in self.done:
            pose = runner.handover_pose()
            if pose is None:
                return
            segment = self.plan[seq]
            self.active = segment
            self.done.add(seq)
            runner.handover_begin(self.make_mission(segment, pose))

    def hand_back(self) -> Segment:
        """The segment's path is done: AUTO is told to go on (retried until it does)."""
        segment = self.active
        assert segment is not None
        self.active, self.handing_back = None, segment
        self.send_set_current(segment.resume_seq)
        self.next_try = time.monotonic() + RETRY_S
        return segment


def local_points(segment: Segment, origin: tuple[float, float],
                 pose: tuple[float, float, float]) -> list[tuple[float, float]]:
    """The segment's path in local (north, east) metres around the EKF origin, from the
    rover's position at hand-over."""
    return [(pose[0], pose[1])] + [geo.ne_from_latlon(lat, lon, origin)
                                   for lat, lon in segment.points]


@dataclass(frozen=True)
class HandoverPlan:
    """What ``run --handover`` read from the vehicle: its segments and its last item."""

    segments: dict[int, Segment]
    last_seq: int


MISSION_CURRENT_ID = 42
MISSION_CURRENT_HZ = 4.0


def attach(plan: HandoverPlan, link: Any, origin: tuple[float, float] | None,
           log: Callable[[str], None]) -> Handover:
    """The loop's Handover on ``link`` (vehicle known, mission placed at ``origin``): asks for
    MISSION_CURRENT at 4 Hz, and hands back with MISSION_SET_CURRENT."""
    from .. import mission as missions
    if origin is None:
        raise UserError("--handover: the vehicle's EKF origin is unknown: its mission "
                        "cannot be placed")
    v = link.vehicle
    result = link.set_message_rate(MISSION_CURRENT_ID, MISSION_CURRENT_HZ)
    if result != 0:
        log(f"MISSION_CURRENT at {MISSION_CURRENT_HZ:g} Hz not confirmed (result {result}): "
            "following the vehicle's own rate")

    def make_mission(segment: Segment, pose: tuple[float, float, float]) -> Any:
        return missions.from_local_points(
            f"hand-over {segment.enable_seq}-{segment.resume_seq}",
            local_points(segment, origin, pose), segment.speed, "the vehicle's mission",
            f"mission items {segment.enable_seq}..{segment.resume_seq} from the rover's pose")

    def set_current(seq: int) -> None:
        link.mav.mission_set_current_send(v.sysid, v.compid, seq)

    return Handover(plan.segments, plan.last_seq, make_mission, set_current, log)
