"""The rover: the paper's eqs. (1)-(2) (Section 5) behind the inner loops a real autopilot has.

    x'   = v cos(phi) - d_cen omega sin(phi)          eq. (1), p = [x, y]
    y'   = v sin(phi) + d_cen omega cos(phi)
    phi' = omega                                      eq. (2)
    v'     = clip(w_c     (u_v - v),         -decel, +accel)         speed channel
    omega' = clip(w_c_yaw (u_omega - omega), -yaw_decel, +yaw_accel) turn-rate channel

Each channel's input is the command after a pure delay, clamped to the vehicle's top speed and
turn rate, and skid-steer mixing takes from both: the speed clamp shrinks while the rover turns
(``turn_speed_coupling`` c), ``|u_v| <= max_speed (1 - c min(1, |omega| / max_yaw_rate))``, and
the turn-rate clamp while it drives (``speed_turn_coupling`` c_w),
``|u_omega| <= max_yaw_rate (1 - c_w min(1, |v| / max_speed))`` (when the motors saturate the
mixer gives up turn rate as well as speed). Both clamps use the state at the step's start.
Without delays, rate limits
or coupling this is the paper's plant (first-order actuators at ``w_c``); with them it is what a
setpoint meets inside ArduPilot Rover (a rate-limited target, a lag, a delay, shared motor range;
the "accel" limit applies while ``|v|`` grows, the "decel" one while it shrinks).

Speed overshoot (``speed_overshoot`` g, ``speed_overshoot_s`` tau): the speed channel's output x
(above) is the speed loop's target; the speed itself overshoots its changes and comes back,
``v = x + g (x - z)``, ``z' = (x - z) / tau`` (:func:`overshoot_step`: ArduPilot's PI speed loop
behind a throttle feed-forward that over-drives, as on SITL's Ackermann ``rover``).

The turn rate's two time scales (``yaw_overshoot`` g_w, ``yaw_overshoot_s`` tau_w): the same
form on the turn-rate channel, ``omega = x + g_w (x - z)``, where g_w may be negative.
ArduPilot's rate loop (``AR_AttitudeControl::get_steering_out_rate``) answers a target change at
once through its feed-forward ``ATC_STR_RAT_FF`` (and P), and the integrator does the rest over
a slower time scale: the fast share 1 + g_w is above one when the feed-forward over-drives the
steering (an overshoot the I term takes back) and below one when it under-drives (a late tail
the I term pulls up). The heading integrates that turn rate exactly over a step
(:func:`overshoot_integral`). The motors cap it: omega stays within the turn-rate clamp the
state leaves (:meth:`RoverModel.tops`, the couplings and limits below), so a skid-steer rover
at speed, whose mixer has less steering left, overshoots less than one at rest
(:func:`turn_rate_cap`; x and z run on uncapped, x kept in the state as ``w_lag``).

``d_cen`` is the paper's distance between the centre of mass (the tracked point p) and the wheel
axle; ``w_c`` the paper's actuator bandwidth omega_c (k_c). The commands are clamped to the
vehicle's top speed and turn rate and held over each step. Works on floats (one rover, e.g. the
bundled MAVLink plant) or arrays (batch simulation).

PX4's velocity-vector interface (``course_gain`` > 0). PX4 rovers take the velocity vector
u_p (the companion's command, LOCAL_NED) and run their own loops: the speed channel gets
``|u_p|`` (PX4's speed setpoint; the same delay, clamp, rate limits and lag as above) and the
turn-rate channel gets PX4's course loop, a proportional heading controller on the course
``atan2(u_y, u_x)`` (RO_YAW_P), clamped to the turn-rate limit (RO_YAW_RATE_LIM):

    u_omega = clip(course_gain * wrap(atan2(u_y, u_x) - phi), +-max_yaw_rate)

An Ackermann rover cannot turn tighter than its steering allows: with ``min_turn_radius`` R
(wheel base / tan(max steering angle)) the turn-rate command is also clamped to
``|u_omega| <= |v| / R`` (v at the step's start; a rover at rest cannot turn at all). The
speed and the course loop's turn rate then take their channels' delays.

Lateral acceleration (``max_lat_accel`` a, ArduPilot's ``ATC_TURN_MAX_G`` x g): ArduPilot
Rover's turn-rate controller (``AR_AttitudeControl::get_steering_out_rate``, every steering
kind) clamps its target to ``a / max(|v|, 1 m/s)`` (``get_turn_rate_from_lat_accel``; below
``LAT_ACCEL_MIN_SPEED`` the limit is taken at that speed), so
``|u_omega| <= a / max(|v|, LAT_ACCEL_MIN_SPEED)`` with v at the step's start.
:meth:`RoverModel.step_vector` is that step.

Integration. Without rate limits the actuators are linear first-order systems with a
held input, so v, omega and phi have exact closed forms over a step, and x, y are the integrals of
known functions of time, taken with Simpson's rule: this *is* RK4 for a right-hand side that
depends on time only, with v, omega, phi exact instead of approximated, and it needs the heading's
sine and cosine at two points per step (mid and end; the start is the previous end) instead of
four. With rate limits each channel is still exact over a step (a ramp at the limit until the
error is small enough, then the exponential; its integral gives the heading), and x, y again
use Simpson's rule. Delays need a fixed step (the commands in flight sit in a ring buffer).

Each channel's step (the rate-limited lag, the overshoot, the motors' cap) is
:mod:`companion.sim.actuator`'s, the delays' ring buffers :mod:`companion.sim.command_delay`'s.
What each piece was built from (the autopilots' measured behaviour): the design note
docs/design/vehicle-model.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..core import ops as _ops
from ..core.signals import Measurement, Num
from .actuator import (
    channel,
    overshoot_integral,
    overshoot_step,
    overshoot_target,
    rate_bounds,
    turn_rate_cap,
)
from .command_delay import CommandDelay

# m/s: ArduPilot takes the lateral-acceleration limit at no less than this speed
# (AR_AttitudeControl.cpp, AR_ATTCONTROL_STEER_SPEED_MIN), so a rover starting off may turn.
LAT_ACCEL_MIN_SPEED = 1.0


@dataclass(frozen=True)
class RoverParams:
    """Vehicle parameters; any numeric field may be a per-vehicle numpy array."""

    d_cen: Num = 0.0
    w_c: Num = 20.0
    w_c_yaw: Num | None = None          # None: same bandwidth as the speed loop (the paper)
    max_speed: Num = math.inf
    max_yaw_rate: Num = math.inf
    max_accel: Num = math.inf             # m/s^2 while |v| grows (ATC_ACCEL_MAX)
    max_decel: Num | None = None          # m/s^2 while |v| shrinks; None: max_accel (ATC_DECEL_MAX)
    max_yaw_accel: Num = math.inf         # rad/s^2 while |omega| grows (ATC_STR_ACC_MAX)
    max_yaw_decel: Num | None = None      # rad/s^2 while |omega| shrinks; None: max_yaw_accel
    speed_delay: Num = 0.0                # s of pure delay before the speed channel
    yaw_delay: Num = 0.0                  # s of pure delay before the turn-rate channel
    turn_speed_coupling: Num = 0.0        # c: share of top speed lost at full turn rate
    speed_turn_coupling: Num = 0.0        # c_w: share of the turn-rate clamp lost at full speed
    course_gain: Num = 0.0                # 1/s: PX4's course loop (> 0: velocity-vector input)
    min_turn_radius: Num = 0.0            # m: Ackermann steering, |omega| <= |v| / R (0: none)
    max_lat_accel: Num = math.inf         # m/s^2: |omega| <= a / max(|v|, 1 m/s) (ATC_TURN_MAX_G g)
    speed_overshoot: Num = 0.0            # g: v = (1 + g) x - g z, the speed loop's overshoot
    speed_overshoot_s: Num = 1.0          # tau, s: z' = (x - z) / tau (how long it takes back)
    yaw_overshoot: Num = 0.0              # g_w > -1: omega = (1 + g_w) x - g_w z (the rate loop's FF)
    yaw_overshoot_s: Num = 1.0            # tau_w, s: z' = (x - z) / tau_w (its integrator's pace)

    @property
    def yaw_bandwidth(self) -> Num:
        return self.w_c if self.w_c_yaw is None else self.w_c_yaw

    @property
    def decel(self) -> Num:
        return self.max_accel if self.max_decel is None else self.max_decel

    @property
    def yaw_decel(self) -> Num:
        return self.max_yaw_accel if self.max_yaw_decel is None else self.max_yaw_decel

    @property
    def is_paper(self) -> bool:
        """No rate limit, delay or coupling anywhere: the paper's linear actuators (exact step)."""
        return not any(_any_finite(v) for v in (self.max_accel, self.decel, self.max_yaw_accel,
                                                 self.yaw_decel)) \
            and not any(_any_positive(v) for v in (self.speed_delay, self.yaw_delay,
                                                   self.turn_speed_coupling,
                                                   self.speed_turn_coupling,
                                                   self.speed_overshoot)) \
            and not _any_nonzero(self.yaw_overshoot)

    @property
    def velocity_vector(self) -> bool:
        """PX4's interface: the commands are u_p (:meth:`RoverModel.step_vector`)."""
        return _any_positive(self.course_gain)

    @property
    def steered_by_radius(self) -> bool:
        """A car on speed / turn-rate setpoints (ArduPilot's Ackermann rover): a turning radius
        and no velocity-vector interface (PX4's course loop keeps its own radius)."""
        return _any_positive(self.min_turn_radius) and not self.velocity_vector

    @property
    def has_delay(self) -> bool:
        return _any_positive(self.speed_delay) or _any_positive(self.yaw_delay)

    @classmethod
    def paper(cls, d_cen: float = 0.0, w_c: float = 20.0) -> RoverParams:
        """Section 5's plant; the paper does not state w_c, we use 20 rad/s."""
        return cls(d_cen=d_cen, w_c=w_c)

    @classmethod
    def stock_rover(cls, d_cen: float = 0.0) -> RoverParams:
        """A stock ArduPilot skid-steer Rover as seen in SITL: about 1.9 s to 90 % of a 1 m/s speed
        step (ln 10 / 1.2 s), top speed 4 m/s, 1 m/s^2 acceleration, 120 deg/s turn rate."""
        return cls(d_cen=d_cen, w_c=1.2, w_c_yaw=1.2, max_speed=4.0,
                   max_yaw_rate=math.radians(120.0), max_accel=1.0)

    def with_(self, **changes: Any) -> RoverParams:
        return replace(self, **changes)


def _any_finite(value: Num) -> bool:
    return bool(np.any(np.isfinite(value)))


def _any_positive(value: Num) -> bool:
    return bool(np.any(np.asarray(value) > 0))


def _any_nonzero(value: Num) -> bool:
    return bool(np.any(np.asarray(value) != 0))


@dataclass(slots=True)
class RoverState:
    """Pose of the tracked point (x, y, yaw) and actuator outputs (speed v, yaw rate omega);
    ``v_slow`` is the speed overshoot's slow state z (unused without ``speed_overshoot``),
    ``w_slow`` the turn rate's (unused without ``yaw_overshoot``) and ``w_lag`` the turn-rate
    lag's own output x (with ``yaw_overshoot``: the motors' cap keeps omega from telling it;
    None: not capped yet, x = :func:`overshoot_target` of omega)."""

    x: Num = 0.0
    y: Num = 0.0
    yaw: Num = 0.0
    v: Num = 0.0
    omega: Num = 0.0
    v_slow: Num = 0.0
    w_slow: Num = 0.0
    w_lag: Num = None


class RoverModel:
    """Eqs. (1)-(2) plus the inner loops. ``step`` returns a new state; the one thing the model
    itself holds is the commands still in flight through a pure delay (:class:`CommandDelay`)."""

    def __init__(self, params: RoverParams = RoverParams(), n: int | None = None):
        self.params = params
        self.n = n
        self._m = _ops.for_size(n)
        self._paper = params.is_paper
        self._course_loop = params.velocity_vector         # u_p in (step_command)
        self._coupled = _any_positive(params.turn_speed_coupling)
        self._turn_coupled = _any_positive(params.speed_turn_coupling)
        self._curvature = _any_positive(params.min_turn_radius)
        self._lateral = _any_finite(params.max_lat_accel)
        self._overshoot = _any_positive(params.speed_overshoot)
        self._yaw_overshoot = _any_nonzero(params.yaw_overshoot)
        self.delay = CommandDelay(params.speed_delay, params.yaw_delay, n) if params.has_delay else None
        self._trig_yaw: Num = None                           # no heading is None: no hit yet
        self._trig_cs: tuple[Num, Num] = (1.0, 0.0)
        self._decay_h: float | None = None
        # which parts of the step any vehicle needs (plant_lanes.SWITCHES)
        self.switches = {"coupled": self._coupled, "turn_coupled": self._turn_coupled,
                         "curvature": self._curvature, "lateral": self._lateral,
                         "overshoot": self._overshoot, "yaw_overshoot": self._yaw_overshoot}

    def _trig(self, yaw: Num) -> tuple[Num, Num]:
        """cos and sin of a heading; the last step's end heading is remembered, so the next step and
        ``measure`` reuse it (trig dominates the cost of a batch step)."""
        if yaw is self._trig_yaw:
            return self._trig_cs
        cs = (self._m.cos(yaw), self._m.sin(yaw))
        self._trig_yaw, self._trig_cs = yaw, cs
        return cs

    def velocity(self, s: RoverState) -> tuple[Num, Num]:
        """Eq. (1): the tracked point's velocity (what LOCAL_POSITION_NED reports as vx, vy)."""
        d = self.params.d_cen
        c, sn = self._trig(s.yaw)
        return s.v * c - d * s.omega * sn, s.v * sn + d * s.omega * c

    def measure(self, s: RoverState) -> Measurement:
        vx, vy = self.velocity(s)
        return Measurement(s.x, s.y, s.yaw, vx, vy, s.omega)

    def _deriv(self, yaw: Num, v: Num, omega: Num, v_cmd: Num,
               w_cmd: Num) -> tuple[Num, Num, Num, Num, Num]:
        """The right-hand side (for the RK4 reference integrator the tests hold the steps to)."""
        m, p = self._m, self.params
        c, sn = m.cos(yaw), m.sin(yaw)
        lat = p.d_cen * omega
        dv = m.clip(p.w_c * (v_cmd - v), *rate_bounds(m, v, p.max_accel, p.decel))
        dw = m.clip(p.yaw_bandwidth * (w_cmd - omega),
                    *rate_bounds(m, omega, p.max_yaw_accel, p.yaw_decel))
        return v * c - lat * sn, v * sn + lat * c, omega, dv, dw

    def clamp_command(self, speed: Num, yaw_rate: Num, omega: Num = 0.0,
                      v: Num = 0.0) -> tuple[Num, Num]:
        """Top speed and turn rate; with coupling, the speed range the turn rate ``omega`` leaves
        and the turn-rate range the speed ``v`` leaves (both the state at the step's start, so
        neither clamp depends on the other's result: the motors share one range); the turning
        radius and the lateral-acceleration limit take turn rate away with speed as well."""
        u, w, _ = self.clamp_with_top(speed, yaw_rate, omega, v)
        return u, w

    def clamp_with_top(self, speed: Num, yaw_rate: Num, omega: Num = 0.0,
                       v: Num = 0.0) -> tuple[Num, Num, Num]:
        """:meth:`clamp_command`, and the top turn rate it clamped to (what caps an
        overshooting turn rate: :func:`turn_rate_cap`)."""
        top, top_w = self.tops(omega, v)
        m = self._m
        return m.clip(speed, -top, top), m.clip(yaw_rate, -top_w, top_w), top_w

    def tops(self, omega: Num = 0.0, v: Num = 0.0) -> tuple[Num, Num]:
        """(top speed, top turn rate) the state (``omega``, ``v``) leaves: what
        :meth:`clamp_command` clamps to, and what caps an overshooting turn rate."""
        m, p = self._m, self.params
        top = p.max_speed
        if self._coupled:
            share = m.minimum(abs(omega) / p.max_yaw_rate, 1.0)
            top = top * (1.0 - p.turn_speed_coupling * share)
        top_w = p.max_yaw_rate
        if self._turn_coupled:
            share_w = m.minimum(abs(v) / p.max_speed, 1.0)
            top_w = top_w * (1.0 - p.speed_turn_coupling * share_w)
        if self._curvature:
            # an Ackermann rover turns at most at |v| / R_min (R_min 0 for some: no limit)
            r = p.min_turn_radius
            if self.n is None:
                top_w = min(top_w, abs(v) / r) if r > 0 else top_w
            else:
                top_w = np.minimum(top_w, abs(v) / np.where(np.asarray(r) > 0, r, 1e-12))
        if self._lateral:
            top_w = m.minimum(top_w, p.max_lat_accel / m.maximum(abs(v), LAT_ACCEL_MIN_SPEED))
        return top, top_w

    def step_vector(self, s: RoverState, ux: Num, uy: Num, dt: float) -> RoverState:
        """Advance ``dt`` seconds with the velocity vector u_p held (PX4's interface, see the
        module docstring): speed |u_p|, turn rate from PX4's course loop on atan2(u_p), then
        each through its channel's delay, as :meth:`step` (what identification fits: the
        course loop's output on the heading of the moment, delayed)."""
        m = self._m
        course_err = m.wrap(m.atan2(uy, ux) - s.yaw)
        return self.step(s, m.hypot(ux, uy), self.params.course_gain * course_err, dt)

    def step_command(self, s: RoverState, speed_cmd: Num, yaw_rate_cmd: Num, dt: float,
                     vector: tuple[Num, Num] | None = None) -> RoverState:
        """Advance ``dt`` seconds on a command as this vehicle takes it: (v_ref, omega_ref)
        (:meth:`step`), or, where the model has PX4's course loop, u_p = ``vector``
        (:meth:`step_vector`; None: the vector of that speed whose course asks the loop for
        that turn rate)."""
        if not self._course_loop:
            return self.step(s, speed_cmd, yaw_rate_cmd, dt)
        if vector is None:
            heading = s.yaw + yaw_rate_cmd / self.params.course_gain
            vector = (speed_cmd * self._m.cos(heading), speed_cmd * self._m.sin(heading))
        return self.step_vector(s, vector[0], vector[1], dt)

    def step(self, s: RoverState, speed_cmd: Num, yaw_rate_cmd: Num, dt: float) -> RoverState:
        """Advance ``dt`` seconds with the commands (v_ref, omega_ref) held (after the delay)."""
        if self.delay is not None:
            speed_cmd, yaw_rate_cmd = self.delay.push(speed_cmd, yaw_rate_cmd, dt)
        u, w, top_w = self.clamp_with_top(speed_cmd, yaw_rate_cmd, s.omega, s.v)
        if self._paper:
            return self._step_exact(s, u, w, dt)
        return self._step_limited(s, u, w, dt, top_w)

    def _step_limited(self, s: RoverState, u: Num, w: Num, h: float,
                      top_w: Num) -> RoverState:
        """Rate-limited channels, exact per channel (:func:`channel`), Simpson for x and y;
        with an overshoot, the channel's output x passes :func:`overshoot_step` (and, for the
        turn rate, the heading takes its integral, :func:`overshoot_integral`, and the motors
        cap it at ``top_w``: :func:`turn_rate_cap`)."""
        m, p = self._m, self.params
        v0, z_end = s.v, s.v_slow
        if self._overshoot:
            v0 = overshoot_target(s.v, s.v_slow, p.speed_overshoot)
        v_mid, v_end, _, _ = channel(m, v0, u, p.w_c, p.max_accel, p.decel, h, integrals=False)
        if self._overshoot:
            (v_mid, _), (v_end, z_end) = (
                overshoot_step(m, v0, x, s.v_slow, p.speed_overshoot, p.speed_overshoot_s, t)
                for x, t in ((v_mid, 0.5 * h), (v_end, h)))
        if not self._yaw_overshoot:
            w_mid, w_end, i_mid, i_end = channel(m, s.omega, w, p.yaw_bandwidth,
                                                  p.max_yaw_accel, p.yaw_decel, h)
            return self._simpson(s, s.yaw + i_mid, s.yaw + i_end, v_mid, v_end, w_mid, w_end, h,
                                 z_end)
        g, tau = p.yaw_overshoot, p.yaw_overshoot_s
        x0 = overshoot_target(s.omega, s.w_slow, g) if s.w_lag is None else s.w_lag
        x_mid, x_end, ix_mid, ix_end = channel(m, x0, w, p.yaw_bandwidth, p.max_yaw_accel,
                                                p.yaw_decel, h)
        (w_mid, _), (w_end, wz_end) = (overshoot_step(m, x0, x, s.w_slow, g, tau, t)
                                       for x, t in ((x_mid, 0.5 * h), (x_end, h)))
        i_mid = overshoot_integral(x0, x_mid, ix_mid, s.w_slow, g, tau, 0.5 * h, m)
        i_end = overshoot_integral(x0, x_end, ix_end, s.w_slow, g, tau, h, m)
        w_mid, w_end, i_mid, i_end = turn_rate_cap(m, s.omega, w_mid, w_end, i_mid, i_end, g,
                                                   top_w, h)
        out = self._simpson(s, s.yaw + i_mid, s.yaw + i_end, v_mid, v_end, w_mid, w_end, h,
                            z_end)
        out.w_slow, out.w_lag = wz_end, x_end
        return out

    def _decays(self, h: float) -> tuple[Num, Num, Num, Num]:
        """e^{-w_c h/2}, e^{-w_c h} and the yaw-loop equivalents, cached for the step size."""
        if self._decay_h != h:
            m, a, b = self._m, self.params.w_c, self.params.yaw_bandwidth
            self._decay = (m.exp(-a * 0.5 * h), m.exp(-a * h), m.exp(-b * 0.5 * h), m.exp(-b * h))
            self._decay_h = h
        return self._decay

    def _step_exact(self, s: RoverState, u: Num, w: Num, h: float) -> RoverState:
        p = self.params
        ea_half, ea, eb_half, eb = self._decays(h)
        b = p.yaw_bandwidth
        dv, dw = s.v - u, s.omega - w               # actuator errors decay as e^{-w_c t}
        v_mid, v_end = u + dv * ea_half, u + dv * ea
        w_mid, w_end = w + dw * eb_half, w + dw * eb
        # phi(t) = phi0 + w t + (omega0 - w)(1 - e^{-b t}) / b
        yaw_mid = s.yaw + w * (0.5 * h) + dw * ((1.0 - eb_half) / b)
        yaw_end = s.yaw + w * h + dw * ((1.0 - eb) / b)
        return self._simpson(s, yaw_mid, yaw_end, v_mid, v_end, w_mid, w_end, h)

    def _simpson(self, s: RoverState, yaw_mid: Num, yaw_end: Num, v_mid: Num, v_end: Num,
                 w_mid: Num, w_end: Num, h: float, v_slow: Num = None) -> RoverState:
        """x, y by Simpson's rule over the step from the heading, speed and turn rate at its
        start, middle and end (each exact); eq. (1) with the d_cen term."""
        m = self._m
        c0, s0 = self._trig(s.yaw)
        c1, s1 = m.cos(yaw_mid), m.sin(yaw_mid)
        c2, s2 = self._trig(yaw_end)
        d = self.params.d_cen
        lat0, lat1, lat2 = d * s.omega, d * w_mid, d * w_end
        h6 = h / 6.0
        x = s.x + h6 * ((s.v * c0 - lat0 * s0) + 4.0 * (v_mid * c1 - lat1 * s1) + (v_end * c2 - lat2 * s2))
        y = s.y + h6 * ((s.v * s0 + lat0 * c0) + 4.0 * (v_mid * s1 + lat1 * c1) + (v_end * s2 + lat2 * c2))
        return RoverState(x, y, yaw_end, v_end, w_end, s.v_slow if v_slow is None else v_slow,
                          s.w_slow)

    def step_rk4(self, s: RoverState, u: Num, w: Num, dt: float) -> RoverState:
        """Classic RK4 on all five states with (u, w) already delayed and clamped: a reference."""
        h2, h6 = 0.5 * dt, dt / 6.0
        d = self._deriv
        k1 = d(s.yaw, s.v, s.omega, u, w)
        k2 = d(s.yaw + h2 * k1[2], s.v + h2 * k1[3], s.omega + h2 * k1[4], u, w)
        k3 = d(s.yaw + h2 * k2[2], s.v + h2 * k2[3], s.omega + h2 * k2[4], u, w)
        k4 = d(s.yaw + dt * k3[2], s.v + dt * k3[3], s.omega + dt * k3[4], u, w)
        return RoverState(
            s.x + h6 * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]),
            s.y + h6 * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]),
            s.yaw + h6 * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2]),
            s.v + h6 * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3]),
            s.omega + h6 * (k1[4] + 2.0 * (k2[4] + k3[4]) + k4[4]),
        )
