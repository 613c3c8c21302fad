"""The excitation manoeuvre of a live ``companion identify``: a tracker that shows the inner loops.

A tracker like :class:`companion.core.pzc.PZCTracker` (``reset()``, ``step(t, measurement,
reference) -> Command``, ``estimate``), so the live loop flies it with every failsafe of
``companion run``. The reference it is given is the start position (the identify mission holds
the start point), which is all it needs of it: home.

The script, for a vehicle whose setpoints may go up to ``max_speed`` and ``max_yaw_rate``:

1. turn rate, in place: small steps both ways (delay and lag), a step to the limit and a reversal
   at the limit (acceleration, deceleration, clamp), a quicker swing;
2. speed, straight (after facing home): small and large steps, a stop, reversing, a reversal
   through zero (acceleration and deceleration both ways);
3. top speed: out from home, face home, full speed through it (the guard below brakes in time);
4. turns at speed, from the middle: full turn rate at 85 % of the expected top speed and at the
   top setpoint (a tracker that saturates both asks for that), both ways and a reversal, so the
   speed the skid-steer mixing leaves shows (coupling);
5. back home and stand still.

Once the script stands at its last segment ("done") the tracker says so (``finished``) and the
live loop ends the manoeuvre there rather than at the identify mission's length (PX4's script is
over at about 57 s of the 85: the rest was the rover standing still).

Staying inside ``space`` metres of home adapts the script to the pose: each step predicts where
the rover would stop if it braked now (half a second at the current speed, then the
deceleration, along the arc of its current turn: braking keeps the turn) and when that is past
``space`` less a margin, and farther out than the rover is now, a *return* takes over: brake,
turn to face home, drive back to within 40 % of the radius; the script then resumes at its next
segment. Turning and returning are data too: the fit uses whatever was commanded.

Which manoeuvre, and how far above the autopilot's limits it asks, is the autopilot profile's
(:func:`manoeuvre`): speed / turn-rate steps for an autopilot that takes them, the velocity-vector
manoeuvre (:class:`VectorExcitation`, nothing on the spot) for one steered by velocity vectors;
and the steering profile's: a rover that cannot turn in place (a car) flies
:class:`CarExcitation` (:func:`car_script`, every turn at speed) instead of the script above.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..core.limits import Limits
from ..core.signals import Command, Estimate, Measurement, Reference
from ..profiles.autopilot import AutopilotProfile
from ..profiles.steering import SteeringProfile
from ..sim.plant import RoverParams

REACTION = 0.5          # s at the current speed before braking bites (delay + lag), for the guard
STOP_STEP = 0.05        # s, the guard's integration step for the stopping arc
BRAKE_TURNING = 0.3     # rad/s: turning faster, the guard brakes on the arc (keeps the turn)
HOME_SPEED = 1.5        # m/s when driving home or out


@dataclass(frozen=True)
class Plan:
    """What the manoeuvre may do: radius (m) around the start, the largest setpoints, the
    deceleration it may count on when predicting a stop (m/s^2, the autopilot's if known), and
    the top speed it expects (None: 80 % of the largest setpoint)."""

    space: float = 10.0
    max_speed: float = 4.0
    max_yaw_rate: float = 2.5
    decel: float = 1.0
    top_speed: float | None = None

    @property
    def expected_top(self) -> float:
        return 0.8 * self.max_speed if self.top_speed is None else min(self.top_speed,
                                                                         self.max_speed)

    @property
    def margin(self) -> float:
        return max(0.5, 0.1 * self.space)

    @property
    def soft_radius(self) -> float:
        return self.space - self.margin


@dataclass(frozen=True)
class Segment:
    kind: str              # hold | face_home | leave | go_home
    duration: float        # s (for face_home / leave / go_home: the longest it may take)
    speed: float = 0.0
    yaw_rate: float = 0.0
    label: str = ""


def script(plan: Plan) -> list[Segment]:
    """The segments of the module docstring for ``plan``."""
    v, w = plan.max_speed, plan.max_yaw_rate
    ws = min(0.5, 0.25 * w)
    v_mid = min(HOME_SPEED, 0.4 * v)
    v_turn = 0.85 * plan.expected_top     # near the top: where the mixing takes speed away
    return [
        # 1. turn rate in place
        Segment("hold", 1.5, 0.0, ws, "turn: small step"),
        Segment("hold", 1.0, 0.0, 0.0),
        Segment("hold", 1.5, 0.0, -ws, "turn: small step back"),
        Segment("hold", 1.0, 0.0, 0.0),
        Segment("hold", 2.0, 0.0, w, "turn: step to the limit"),
        Segment("hold", 2.5, 0.0, -w, "turn: reversal at the limit"),
        Segment("hold", 1.5, 0.0, 0.0),
        Segment("hold", 1.0, 0.0, 0.6 * w, "turn: swing"),
        Segment("hold", 1.0, 0.0, -0.6 * w),
        Segment("hold", 1.0, 0.0, 0.0),
        # 2. speed, straight
        Segment("face_home", 4.0, 0.0, 0.5 * w, "speed: face home"),
        Segment("hold", 2.0, min(0.5, v), 0.0, "speed: small step"),
        Segment("hold", 2.5, v_mid, 0.0, "speed: step"),
        Segment("hold", 2.0, 0.0, 0.0, "speed: stop"),
        Segment("hold", 2.0, -min(1.0, v), 0.0, "speed: reverse"),
        Segment("hold", 1.5, 0.0, 0.0),
        Segment("hold", 1.0, min(1.0, v), 0.0, "speed: reversal through zero"),
        Segment("hold", 2.5, -min(1.0, v), 0.0),
        Segment("hold", 1.5, 0.0, 0.0),
        # 3. top speed through home
        Segment("leave", 8.0, min(HOME_SPEED, v), 0.0, "top speed: out"),
        Segment("hold", 1.5, 0.0, 0.0),
        Segment("face_home", 5.0, 0.0, 0.5 * w, "top speed: face home"),
        Segment("hold", 8.0, v, 0.0, "top speed: full speed"),
        Segment("hold", 2.0, 0.0, 0.0),
        # 4. turns at speed (coupling): the speed builds while turning, so the circles stay
        # small (radius v / omega) and the rover near where it began them
        Segment("face_home", 4.0, 0.0, 0.5 * w, "coupling: face home"),
        Segment("go_home", 6.0, min(HOME_SPEED, v), 0.5 * w, "coupling: to the middle"),
        Segment("hold", 3.5, v_turn, w, "coupling: full turn at speed"),
        Segment("hold", 3.0, v, w, "coupling: full turn, full speed asked"),
        Segment("hold", 3.0, v, -w, "coupling: figure eight at full speed"),
        Segment("hold", 3.0, v, w),
        Segment("hold", 3.0, v_turn, -w, "coupling: reversal at speed"),
        Segment("hold", 2.0, 0.0, 0.0),
        # 5. home
        Segment("go_home", 12.0, min(HOME_SPEED, v), 0.5 * w, "home"),
        Segment("hold", math.inf, 0.0, 0.0, "done"),
    ]


@dataclass(frozen=True)
class Home:
    """The reference the manoeuvre is flown against: the start point, held (a trajectory in the
    mission's "start" frame, so the live loop anchors it where the rover starts)."""

    duration: float | None = None

    def sample(self, t: float) -> Reference:
        return Reference(0.0, 0.0)


def _wrap(angle: float) -> float:
    return math.remainder(angle, math.tau)


class Excitation:
    """The tracker: ``step`` returns the script's command, or the guard's while it returns."""

    name = "excitation"

    def __init__(self, plan: Plan):
        self.plan = plan
        self.segments = script(plan)
        self.index = 0
        self.estimate: Estimate | None = None
        self.returns = 0                   # times the guard brought the rover back
        self.max_distance = 0.0            # m from home, the farthest seen
        self._home: tuple[float, float] | None = None
        self._seg_t0: float | None = None
        self._guard: str | None = None     # None, "brake", "turn", "drive"
        self._guard_t0 = 0.0
        self._last: tuple[float, float, float] | None = None   # t, x, y for a speed estimate
        self._v_pos = 0.0
        self._rate = 0.0                   # the turn-rate setpoint last sent
        self._brake_rate = 0.0

    @property
    def phase(self) -> str:
        """What the rover is doing now (for logs)."""
        if self._guard is not None:
            return f"return: {self._guard}"
        seg = self.segments[min(self.index, len(self.segments) - 1)]
        return seg.label or seg.kind

    @property
    def finished(self) -> bool:
        """The script is over: the rover home and standing still (its last segment)."""
        return self._guard is None and self.index == len(self.segments) - 1

    def reset(self) -> None:
        """After a failsafe or a gap: the current segment starts again from its beginning."""
        self._seg_t0 = None
        self._last = None
        self._v_pos = 0.0
        if self._guard is not None:
            self._guard, self._guard_t0 = "brake", math.nan

    def step(self, t: float, meas: Measurement, ref: Reference) -> Command:
        self.estimate = Estimate(meas.x, meas.y, meas.yaw, meas.vx, meas.vy, meas.yaw_rate)
        if self._home is None:
            self._home = (ref.x, ref.y)
        speed = self._speed(t, meas)
        dx, dy = meas.x - self._home[0], meas.y - self._home[1]
        dist = math.hypot(dx, dy)
        self.max_distance = max(self.max_distance, dist)
        if self._guard is None and self._heading_out(meas.yaw, meas.yaw_rate, dx, dy, dist, speed):
            self._guard, self._guard_t0 = "brake", t
            # Braking keeps the turn it is in: the rover then stops on the arc it predicted.
            self._brake_rate = self._rate if abs(meas.yaw_rate) > BRAKE_TURNING else 0.0
            self.returns += 1
        if self._guard is not None:
            cmd = self._return(t, meas.yaw, dx, dy, dist, speed)
            if cmd is not None:
                return self._command(cmd, meas.yaw)
            self._advance(t)               # back within reach: on with the next segment
        return self._command(self._scripted(t, meas.yaw, dx, dy, dist, speed), meas.yaw)

    # --- the guard ------------------------------------------------------------------------------
    def _speed(self, t: float, meas: Measurement) -> float:
        """Signed speed along the heading: the vehicle's velocity, or (when it reports none)
        the pose's rate of change, whichever is larger."""
        along = meas.vx * math.cos(meas.yaw) + meas.vy * math.sin(meas.yaw)
        if self._last is not None and t > self._last[0]:
            dt = t - self._last[0]
            raw = math.hypot(meas.x - self._last[1], meas.y - self._last[2]) / dt
            self._v_pos += min(1.0, dt / 0.2) * (raw - self._v_pos)     # 0.2 s smoothing
        self._last = (t, meas.x, meas.y)
        if abs(along) >= self._v_pos:
            return along
        return math.copysign(self._v_pos, along) if along else self._v_pos

    def stop_point(self, yaw: float, omega: float, dx: float, dy: float,
                   speed: float) -> tuple[float, float]:
        """Where the rover would stop (relative to home) if it braked now: REACTION seconds at
        this speed, then ``decel``, on the arc of its current turn rate (braking keeps the
        turn; turning slower than BRAKE_TURNING it brakes straight)."""
        if abs(omega) <= BRAKE_TURNING:
            omega = 0.0
        x, y, h, v, t = dx, dy, yaw, speed, 0.0
        while v != 0.0 and t < 20.0:
            x += v * math.cos(h) * STOP_STEP
            y += v * math.sin(h) * STOP_STEP
            h += omega * STOP_STEP
            t += STOP_STEP
            if t > REACTION:
                v = math.copysign(max(abs(v) - self.plan.decel * STOP_STEP, 0.0), v)
        return x, y

    def _heading_out(self, yaw: float, omega: float, dx: float, dy: float, dist: float,
                     speed: float) -> bool:
        """Would the rover, braking now, stop outside the soft radius, farther out than now?"""
        sx, sy = self.stop_point(yaw, omega, dx, dy, speed)
        stop = math.hypot(sx, sy)
        return (stop > self.plan.soft_radius and stop > dist) \
            or dist > self.plan.soft_radius + 0.5 * self.plan.margin

    def _return(self, t: float, yaw: float, dx: float, dy: float, dist: float,
                speed: float) -> tuple[float, float] | None:
        """The return's command, or None once the rover is back within 40 % of the radius."""
        if math.isnan(self._guard_t0):
            self._guard_t0 = t
        elapsed = t - self._guard_t0
        if self._guard == "brake":
            if (abs(speed) < 0.15 and elapsed > 0.5) or elapsed > 4.0:
                self._guard, self._guard_t0 = "turn", t
            return 0.0, self._brake_rate
        if self._guard == "turn":
            err = _wrap(math.atan2(-dy, -dx) - yaw)
            if abs(err) < 0.2 or elapsed > 5.0:
                self._guard, self._guard_t0 = "drive", t
            return 0.0, self._turn_toward(err, 0.5 * self.plan.max_yaw_rate)
        if dist < 0.4 * self.plan.space or elapsed > 15.0:
            self._guard = None
            return None
        return self._drive_home(yaw, dx, dy, dist)

    def _turn_toward(self, err: float, rate: float) -> float:
        return max(-rate, min(rate, 2.0 * err))

    def _drive_home(self, yaw: float, dx: float, dy: float, dist: float) -> tuple[float, float]:
        err = _wrap(math.atan2(-dy, -dx) - yaw)
        speed = min(HOME_SPEED, self.plan.max_speed, 0.7 * dist) * max(0.0, math.cos(err))
        return speed, self._turn_toward(err, 0.5 * self.plan.max_yaw_rate)

    # --- the script -----------------------------------------------------------------------------
    def _advance(self, t: float) -> None:
        self.index = min(self.index + 1, len(self.segments) - 1)
        self._seg_t0 = t

    def _scripted(self, t: float, yaw: float, dx: float, dy: float, dist: float,
                  speed: float) -> tuple[float, float]:
        if self._seg_t0 is None:
            self._seg_t0 = t
        while True:
            seg = self.segments[self.index]
            elapsed = t - self._seg_t0
            if elapsed >= seg.duration:
                self._advance(t)
                continue
            if seg.kind == "hold":
                return seg.speed, seg.yaw_rate
            err = _wrap(math.atan2(-dy, -dx) - yaw)
            if seg.kind == "face_home":
                if dist < 1.5 or abs(err) < 0.1:
                    self._advance(t)
                    continue
                return 0.0, self._turn_toward(err, seg.yaw_rate)
            if seg.kind == "leave":
                if dist > 0.7 * self.plan.soft_radius:
                    self._advance(t)
                    continue
                return seg.speed, 0.0
            if seg.kind == "go_home":
                if dist < 0.5 and abs(speed) < 0.2:
                    self._advance(t)
                    continue
                return self._drive_home(yaw, dx, dy, dist)
            raise ValueError(f"unknown segment kind {seg.kind!r}")

    def describe(self) -> str:
        p = self.plan
        return (f"manoeuvre within {p.space:g} m: setpoints up to {p.max_speed:.2f} m/s, "
                f"{p.max_yaw_rate:.2f} rad/s")

    def _command(self, cmd: tuple[float, float], yaw: float) -> Command:
        p = self.plan
        speed = max(-p.max_speed, min(p.max_speed, cmd[0]))
        rate = max(-p.max_yaw_rate, min(p.max_yaw_rate, cmd[1]))
        self._rate = rate
        return Command(speed, rate, speed * math.cos(yaw), speed * math.sin(yaw))


# --------------------------------------------------------------------------- a car

CAR_TURN = 1.0          # rad/s a car is counted on to turn at when planning its way back
CAR_MIN_SPEED = 0.8     # m/s: a car turning home keeps at least this (it cannot turn at rest)


def car_script(plan: Plan) -> list[Segment]:
    """The segments for a rover that cannot turn in place (a car: ArduPilot's Ackermann
    rover): every turn is flown at speed, so each shows the turn rate the steering gives at
    that speed (the turning radius at low speed, the steering and turn-rate limits above):

    1. off, straight, at a walk; small turn-rate steps both ways (delay and lag at speed);
    2. faster: a speed step, a turn-rate step to the limit and its reversal (the clamp, the
       turn-rate acceleration), a swing;
    3. slow and tight: full turn-rate setpoints at a crawl (the turning radius, |v| / R);
    4. a stop, reversing straight and turning (reversing), a stop;
    5. fast: a speed step towards the top the space allows, a swing there, a stop from speed
       (deceleration);
    6. stand still.
    Between the parts ``steer_home`` turns back towards home at speed (a car's "face home");
    the guard of :class:`Excitation` keeps it within the space by steering home at speed."""
    v, w = plan.max_speed, plan.max_yaw_rate
    ws = min(0.4, 0.25 * w)
    v_lo = min(1.0, 0.4 * v)
    v_mid = min(2.0, 0.6 * v)
    # as fast as the space allows: a straight of about half its radius, accelerating at ~1 m/s^2
    v_hi = min(0.8 * plan.expected_top, math.sqrt(max(plan.space, 1.0) * 0.9), v)
    v_crawl = min(0.5, 0.3 * v)
    home = min(HOME_SPEED, v)
    return [
        Segment("hold", 2.5, v_lo, 0.0, "car: off at a walk"),
        Segment("hold", 1.5, v_lo, ws, "car: small turn step"),
        Segment("hold", 1.5, v_lo, -ws, "car: small turn step back"),
        Segment("hold", 1.0, v_lo, 0.0),
        Segment("steer_home", 5.0, home, w, "car: steer home"),
        Segment("hold", 2.0, v_mid, 0.0, "car: speed step"),
        Segment("hold", 2.0, v_mid, w, "car: turn step to the limit at speed"),
        Segment("hold", 2.0, v_mid, -w, "car: reversal at the limit"),
        Segment("hold", 1.0, v_mid, 0.6 * w, "car: swing"),
        Segment("hold", 1.0, v_mid, -0.6 * w),
        Segment("steer_home", 5.0, home, w, "car: steer home"),
        Segment("hold", 2.0, v_crawl, 0.0, "car: crawl"),
        Segment("hold", 2.5, v_crawl, w, "car: tight turn at a crawl"),
        Segment("hold", 2.5, v_crawl, -w, "car: tight turn back"),
        Segment("hold", 1.5, 0.0, 0.0, "car: stop"),
        Segment("hold", 2.5, -v_lo, 0.0, "car: reverse"),
        Segment("hold", 2.0, -v_lo, 0.5 * w, "car: reversing turn"),
        Segment("hold", 1.5, 0.0, 0.0, "car: stop"),
        Segment("steer_home", 6.0, home, w, "car: steer home"),
        Segment("hold", 3.0, v_hi, 0.0, "car: fast"),
        Segment("hold", 1.5, v_hi, 0.5 * w, "car: swing fast"),
        Segment("hold", 1.5, v_hi, -0.5 * w),
        Segment("hold", 2.5, 0.0, 0.0, "car: stop from speed"),
        Segment("steer_home", 6.0, home, w, "car: steer home"),
        Segment("hold", 2.0, v_mid, 0.3 * w, "car: arc"),
        Segment("hold", 2.0, 0.0, 0.0),
        Segment("hold", math.inf, 0.0, 0.0, "done"),
    ]


class CarExcitation(Excitation):
    """The manoeuvre of :func:`car_script`. Its guard differs from :class:`Excitation`'s: a car
    cannot brake and turn on the spot, so it steers home at speed (at least CAR_MIN_SPEED,
    slowing to that first) and starts doing so a turning circle earlier."""

    def __init__(self, plan: Plan):
        super().__init__(plan)
        self.segments = car_script(plan)

    @property
    def _turn_room(self) -> float:
        """m: the diameter of the circle a car steering home at HOME_SPEED drives."""
        return 2.0 * min(HOME_SPEED, self.plan.max_speed) / min(CAR_TURN, self.plan.max_yaw_rate)

    def _heading_out(self, yaw: float, omega: float, dx: float, dy: float, dist: float,
                     speed: float) -> bool:
        sx, sy = self.stop_point(yaw, omega, dx, dy, speed)
        stop = math.hypot(sx, sy)
        soft = self.plan.soft_radius - self._turn_room
        outward = dx * math.cos(yaw) + dy * math.sin(yaw) > 0 if speed >= 0 else \
            dx * math.cos(yaw) + dy * math.sin(yaw) < 0
        return (stop > max(soft, 0.3 * self.plan.space) and stop > dist and outward) \
            or dist > self.plan.soft_radius + 0.5 * self.plan.margin

    def _return(self, t: float, yaw: float, dx: float, dy: float, dist: float,
                speed: float) -> tuple[float, float] | None:
        if math.isnan(self._guard_t0):
            self._guard_t0 = t
        self._guard = "drive"
        err = _wrap(math.atan2(-dy, -dx) - yaw)
        if (dist < 0.4 * self.plan.space and abs(err) < 0.5) or t - self._guard_t0 > 20.0:
            self._guard = None
            return None
        return self._steer_home(yaw, dx, dy, min(HOME_SPEED, self.plan.max_speed),
                                self.plan.max_yaw_rate)

    def _steer_home(self, yaw: float, dx: float, dy: float, speed: float,
                    rate: float) -> tuple[float, float]:
        """Forward at ``speed`` (no less than CAR_MIN_SPEED while far off course, to turn),
        turning towards home."""
        err = _wrap(math.atan2(-dy, -dx) - yaw)
        v = max(min(CAR_MIN_SPEED, speed), speed * max(0.0, math.cos(err)))
        return v, self._turn_toward(err, rate)

    def _scripted(self, t: float, yaw: float, dx: float, dy: float, dist: float,
                  speed: float) -> tuple[float, float]:
        if self._seg_t0 is None:
            self._seg_t0 = t
        while True:
            seg = self.segments[self.index]
            if t - self._seg_t0 >= seg.duration:
                self._advance(t)
                continue
            if seg.kind == "steer_home":
                err = _wrap(math.atan2(-dy, -dx) - yaw)
                if dist < 1.5 or abs(err) < 0.3:
                    self._advance(t)
                    continue
                return self._steer_home(yaw, dx, dy, seg.speed, seg.yaw_rate)
            return super()._scripted(t, yaw, dx, dy, dist, speed)

    def describe(self) -> str:
        p = self.plan
        return (f"car manoeuvre (turns at speed) within {p.space:g} m: setpoints up to "
                f"{p.max_speed:.2f} m/s, {p.max_yaw_rate:.2f} rad/s")


# --------------------------------------------------------------------------- PX4

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
                                    home, _wrap(home - meas.yaw))
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


def manoeuvre(profile: AutopilotProfile, prior: RoverParams, space: float,
              limits: Limits, steering: SteeringProfile | None = None
              ) -> Excitation | CarExcitation | VectorExcitation:
    """The excitation tracker for a vehicle of this autopilot whose priors are ``prior``: within
    ``space`` m, setpoints up to the profile's headroom x the autopilot's limits (so the clamps
    show) and no more than the companion's ``limits``; the velocity-vector manoeuvre where the
    profile's setpoints are velocity vectors; the car's (every turn at speed) for a
    ``steering`` kind that does not turn in place."""
    h = profile.ident.headroom
    plan = Plan(space=space, max_speed=min(limits.max_speed, h * prior.max_speed),
                max_yaw_rate=min(limits.max_yaw_rate, h * prior.max_yaw_rate),
                decel=min(prior.decel, prior.max_accel), top_speed=prior.max_speed)
    if profile.setpoint.velocity_vector:
        return VectorExcitation(plan)
    if steering is not None and not steering.turns_in_place:
        return CarExcitation(plan)
    return Excitation(plan)
