"""The excitation manoeuvre of a vehicle driven by velocity vectors (PX4's setpoints: the autopilot profile's ``manoeuvre = "velocity vectors"``).

PX4 runs its own speed and course loops on u_p, so the manoeuvre is a script of speeds and
course steps (:func:`vector_script`) with nothing on the spot (an Ackermann rover cannot turn
there); its guard sends the rover home whenever it would leave the space
(:class:`VectorExcitation`). The plan is :mod:`companion.ident.excite`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..core.signals import Command, Estimate, Measurement, Reference
from .excite import HOME_SPEED, Plan, wrap


@dataclass(frozen=True)
class CourseSegment:
    """One piece of the velocity-vector manoeuvre: ``speed`` (m/s) for ``duration`` s along a
    course ``offset`` rad off the heading at the segment's start (a course step), or, with
    ``circle`` set, a course kept ``offset`` ahead of the current heading (a steady turn)."""

    duration: float
    speed: float
    offset: float = 0.0
    circle: bool = False
    label: str = ""


def vector_script(plan: Plan) -> list[CourseSegment]:
    """The manoeuvre for a vehicle driven by velocity vectors (PX4: its own speed and course
    loops; an Ackermann rover cannot turn on the spot, so nothing here asks it to):

    1. speed steps on a gentle circle (delay, lag, acceleration and deceleration, the clamp);
    2. course steps at a moderate speed, small and large, both ways (the course gain, the
       turn-rate clamp and its rate limits);
    3. large course steps slowly (the rover turns at |v| / R_min: the turning radius);
    4. a stop.
    The guard of :class:`VectorExcitation` turns the rover back towards home whenever it would
    leave ``space``."""
    v = plan.max_speed
    v_lo, v_mid = min(0.6, 0.2 * v), min(HOME_SPEED, 0.45 * v)
    v_hi = min(0.8 * plan.expected_top, math.sqrt(max(plan.space, 1.0) * 1.2))
    gentle = 0.25                                    # rad of course lead: a wide circle
    return [
        CourseSegment(2.0, 0.0, 0.0, False, "still"),
        CourseSegment(4.0, v_lo, gentle, True, "speed step small"),
        CourseSegment(4.0, v_mid, gentle, True, "speed step"),
        CourseSegment(4.0, v_hi, gentle, True, "speed step large"),
        CourseSegment(3.0, v_lo, gentle, True, "slow down"),
        CourseSegment(3.0, v_mid, 0.3, False, "course +0.3"),
        CourseSegment(3.0, v_mid, -0.3, False, "course -0.3"),
        CourseSegment(3.0, v_mid, 1.2, False, "course +1.2"),
        CourseSegment(3.0, v_mid, -1.2, False, "course -1.2"),
        CourseSegment(3.0, v_mid, 2.5, False, "course +2.5"),
        CourseSegment(3.0, v_mid, -2.5, False, "course -2.5"),
        CourseSegment(4.0, v_lo, 2.8, True, "tight turn slow +"),
        CourseSegment(4.0, v_lo, -2.8, True, "tight turn slow -"),
        CourseSegment(4.0, v_mid, 2.8, True, "tight turn +"),
        CourseSegment(3.0, v_hi, 0.0, False, "straight fast"),
        CourseSegment(3.0, 0.0, 0.0, False, "stop"),
        CourseSegment(math.inf, 0.0, 0.0, False, "done"),
    ]


class VectorExcitation:
    """The excitation tracker for a velocity-vector vehicle (PX4): ``step`` returns the script's
    velocity vector u_p = speed (cos course, sin course) (``speed`` and ``yaw_rate`` carry the
    speed and the course offset asked, for the logs). While the rover heads out beyond
    ``space`` less a margin it is sent towards home at a moderate speed instead (a return),
    then the script goes on with its next segment."""

    name = "excitation"

    def __init__(self, plan: Plan):
        self.plan = plan
        self.segments = vector_script(plan)
        self.index = 0
        self.estimate: Estimate | None = None
        self.returns = 0
        self.max_distance = 0.0
        self._home: tuple[float, float] | None = None
        self._seg_t0: float | None = None
        self._course: float | None = None
        self._returning = False

    @property
    def phase(self) -> str:
        if self._returning:
            return "return"
        return self.segments[min(self.index, len(self.segments) - 1)].label

    @property
    def finished(self) -> bool:
        """The script is over: the rover stopped (its last segment)."""
        return not self._returning and self.index == len(self.segments) - 1

    def reset(self) -> None:
        self._seg_t0 = None
        self._course = None

    def step(self, t: float, meas: Measurement, ref: Reference) -> Command:
        self.estimate = Estimate(meas.x, meas.y, meas.yaw, meas.vx, meas.vy, meas.yaw_rate)
        if self._home is None:
            self._home = (ref.x, ref.y)
        dx, dy = meas.x - self._home[0], meas.y - self._home[1]
        dist = math.hypot(dx, dy)
        self.max_distance = max(self.max_distance, dist)
        p = self.plan
        outward = dx * meas.vx + dy * meas.vy > 0
        if not self._returning and dist > p.soft_radius - 1.0 and outward:
            self._returning = True
            self.returns += 1
        if self._returning:
            if dist > 0.4 * p.space:
                home = math.atan2(-dy, -dx)
                return self._vector(min(HOME_SPEED, p.max_speed, 0.5 * p.max_speed + 0.5),
                                    home, wrap(home - meas.yaw))
            self._returning = False
            self._advance(t)
        if self._seg_t0 is None:
            self._seg_t0 = t
        seg = self.segments[self.index]
        if t - self._seg_t0 >= seg.duration:
            self._advance(t)
            seg = self.segments[self.index]
        if seg.circle or self._course is None:
            self._course = meas.yaw + seg.offset
        return self._vector(seg.speed, self._course, seg.offset)

    def _advance(self, t: float) -> None:
        self.index = min(self.index + 1, len(self.segments) - 1)
        self._seg_t0, self._course = t, None

    def describe(self) -> str:
        return (f"velocity-vector manoeuvre within {self.plan.space:g} m: up to "
                f"{self.plan.max_speed:.2f} m/s")

    def _vector(self, speed: float, course: float, offset: float) -> Command:
        speed = max(0.0, min(self.plan.max_speed, speed))
        return Command(speed, offset, speed * math.cos(course), speed * math.sin(course))
