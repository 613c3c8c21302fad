"""The excitation manoeuvre of a rover that cannot turn in place (a car: the Ackermann steering profile's, ``manoeuvre = "turns at speed"``).

Every turn is flown at speed (:func:`car_script`); its guard steers home at speed rather than
braking and turning on the spot (:class:`CarExcitation`). The rest, the plan, the segments and
the guard's prediction of a stop, is :mod:`companion.ident.excite`'s.
"""

from __future__ import annotations

import math

from .excite import HOME_SPEED, STILL_S, Excitation, Plan, Segment, wrap

CAR_TURN = 1.0          # rad/s a car is counted on to turn at when planning its way back
CAR_MIN_SPEED = 0.8     # m/s: a car turning home keeps at least this (it cannot turn at rest)


def car_script(plan: Plan) -> list[Segment]:
    """The segments for a rover that cannot turn in place (a car: ArduPilot's Ackermann
    rover): every turn is flown at speed, so each shows the turn rate the steering gives at
    that speed (the turning radius at low speed, the steering and turn-rate limits above):

    0. stand still (the estimate's noise: :mod:`companion.ident.noise`);
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
        Segment("hold", STILL_S, 0.0, 0.0, "still: the estimate's noise"),
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
        err = wrap(math.atan2(-dy, -dx) - yaw)
        if (dist < 0.4 * self.plan.space and abs(err) < 0.5) or t - self._guard_t0 > 20.0:
            self._guard = None
            return None
        return self._steer_home(yaw, dx, dy, min(HOME_SPEED, self.plan.max_speed),
                                self.plan.max_yaw_rate)

    def _steer_home(self, yaw: float, dx: float, dy: float, speed: float,
                    rate: float) -> tuple[float, float]:
        """Forward at ``speed`` (no less than CAR_MIN_SPEED while far off course, to turn),
        turning towards home."""
        err = wrap(math.atan2(-dy, -dx) - yaw)
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
                err = wrap(math.atan2(-dy, -dx) - yaw)
                if dist < 1.5 or abs(err) < 0.3:
                    self._advance(t)
                    continue
                return self._steer_home(yaw, dx, dy, seg.speed, seg.yaw_rate)
            return super()._scripted(t, yaw, dx, dy, dist, speed)

    def describe(self) -> str:
        p = self.plan
        return (f"car manoeuvre (turns at speed) within {p.space:g} m: setpoints up to "
                f"{p.max_speed:.2f} m/s, {p.max_yaw_rate:.2f} rad/s")
