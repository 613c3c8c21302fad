"""The excitation manoeuvre of a live ``companion identify``: a tracker that shows the inner loops.

A tracker like :class:`companion.core.pzc.PZCTracker` (``reset()``, ``step(t, measurement,
reference) -> Command``, ``estimate``), so the live loop flies it with every failsafe of
``companion run``. The reference it is given is the start position (the identify mission holds
the start point), which is all it needs of it: home.

The script, for a vehicle whose setpoints may go up to ``max_speed`` and ``max_yaw_rate``,
after ``STILL_S`` s standing still (the pose estimate's noise, :mod:`companion.ident.noise`):

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

Which manoeuvre, and how far above the autopilot's limits it asks, the profiles say
(:func:`manoeuvre`): an autopilot steered by velocity vectors names its own (PX4's,
:mod:`companion.ident.excite_vector`, nothing on the spot); otherwise the steering kind's: the
script above for one that turns in place, :mod:`companion.ident.excite_car` (every turn at
speed) for a car. Each is a module, found by the name its profile gives (:func:`manoeuvres`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..core.limits import Limits
from ..core.signals import Command, Estimate, Measurement, Reference
from ..profiles import model_steering
from ..profiles.autopilot import AutopilotProfile
from ..profiles.steering import SteeringProfile
from ..sim.plant import RoverParams

if TYPE_CHECKING:
    from .excite_vector import VectorExcitation

REACTION = 0.5          # s at the current speed before braking bites (delay + lag), for the guard
STOP_STEP = 0.05        # s, the guard's integration step for the stopping arc
BRAKE_TURNING = 0.3     # rad/s: turning faster, the guard brakes on the arc (keeps the turn)
HOME_SPEED = 1.5        # m/s when driving home or out
STILL_S = 3.0           # s standing still first: the estimate's noise (ident.noise: >= 2 s)


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
        Segment("hold", STILL_S, 0.0, 0.0, "still: the estimate's noise"),
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


def wrap(angle: float) -> float:
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
            err = wrap(math.atan2(-dy, -dx) - yaw)
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
        err = wrap(math.atan2(-dy, -dx) - yaw)
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
            err = wrap(math.atan2(-dy, -dx) - yaw)
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


# --------------------------------------------------------------------------- which one

IN_PLACE, AT_SPEED, VECTORS = "turns in place", "turns at speed", "velocity vectors"


def manoeuvres() -> dict[str, type[Excitation] | type[VectorExcitation]]:
    """The manoeuvres by the name a profile gives (``IdentFacts.manoeuvre`` of an autopilot
    that flies its own whatever steers the rover, else ``SteeringProfile.manoeuvre``). A new
    one: a module beside this (``excite_car.py``, ``excite_vector.py``) and a line here."""
    from .excite_car import CarExcitation  # they build on this module
    from .excite_vector import VectorExcitation
    return {IN_PLACE: Excitation, AT_SPEED: CarExcitation, VECTORS: VectorExcitation}


def manoeuvre(profile: AutopilotProfile, prior: RoverParams, space: float,
              limits: Limits, steering: SteeringProfile | None = None
              ) -> Excitation | VectorExcitation:
    """The excitation tracker for a vehicle of this autopilot whose priors are ``prior``: within
    ``space`` m, setpoints up to the profile's headroom x the autopilot's limits (so the clamps
    show) and no more than the companion's ``limits``; the autopilot's own manoeuvre where its
    profile names one (PX4's velocity vectors), else the ``steering`` kind's (the car's flies
    every turn at speed; none known: the vehicle model's kind, which turns in place)."""
    h = profile.ident.headroom
    plan = Plan(space=space, max_speed=min(limits.max_speed, h * prior.max_speed),
                max_yaw_rate=min(limits.max_yaw_rate, h * prior.max_yaw_rate),
                decel=min(prior.decel, prior.max_accel), top_speed=prior.max_speed)
    name = profile.ident.manoeuvre or (steering or model_steering()).manoeuvre
    return manoeuvres()[name](plan)
