"""The rover the paper simulates (Section 5): eqs. (1)-(2) with first-order actuators.

    x'   = v cos(phi) - d_cen omega sin(phi)          eq. (1), p = [x, y]
    y'   = v sin(phi) + d_cen omega cos(phi)
    phi' = omega                                      eq. (2)
    v'     = w_c     (v_ref - v)       (clipped to +-max_accel)
    omega' = w_c_yaw (omega_ref - omega)

``d_cen`` is the paper's distance between the centre of mass (the tracked point p) and the wheel
axle; ``w_c`` the paper's actuator bandwidth omega_c (k_c). The commands are clamped to the
vehicle's top speed and turn rate and held over each step. Works on floats (one rover, e.g. the
bundled MAVLink plant) or arrays (batch simulation).

Integration. Without an acceleration limit the actuators are linear first-order systems with a
held input, so v, omega and phi have exact closed forms over a step, and x, y are the integrals of
known functions of time, taken with Simpson's rule: this *is* RK4 for a right-hand side that
depends on time only, with v, omega, phi exact instead of approximated, and it needs the heading's
sine and cosine at two points per step (mid and end; the start is the previous end) instead of
four. With an acceleration limit (a non-smooth clip) classic RK4 on all five states is used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ..core import ops as _ops
from ..core.signals import Measurement, Num


@dataclass(frozen=True)
class RoverParams:
    """Vehicle parameters; any numeric field may be a per-vehicle numpy array."""

    d_cen: Num = 0.0
    w_c: Num = 20.0
    w_c_yaw: Num | None = None          # None: same bandwidth as the speed loop (the paper)
    max_speed: float = math.inf
    max_yaw_rate: float = math.inf
    max_accel: float = math.inf

    @property
    def yaw_bandwidth(self) -> Num:
        return self.w_c if self.w_c_yaw is None else self.w_c_yaw

    @classmethod
    def paper(cls, d_cen: float = 0.0, w_c: float = 20.0) -> "RoverParams":
        """Section 5's plant; the paper does not state w_c, we use 20 rad/s."""
        return cls(d_cen=d_cen, w_c=w_c)

    @classmethod
    def stock_rover(cls, d_cen: float = 0.0) -> "RoverParams":
        """A stock ArduPilot skid-steer Rover as seen in SITL: about 1.9 s to 90 % of a 1 m/s speed
        step (ln 10 / 1.2 s), top speed 4 m/s, 1 m/s^2 acceleration, 120 deg/s turn rate."""
        return cls(d_cen=d_cen, w_c=1.2, w_c_yaw=1.2, max_speed=4.0,
                   max_yaw_rate=math.radians(120.0), max_accel=1.0)

    def with_(self, **changes) -> "RoverParams":
        return replace(self, **changes)


@dataclass(slots=True)
class RoverState:
    """Pose of the tracked point (x, y, yaw) and actuator outputs (speed v, yaw rate omega)."""

    x: Num = 0.0
    y: Num = 0.0
    yaw: Num = 0.0
    v: Num = 0.0
    omega: Num = 0.0


class RoverModel:
    """Eqs. (1)-(2) plus actuators, integrated with RK4. Stateless: ``step`` returns a new state."""

    def __init__(self, params: RoverParams = RoverParams(), n: int | None = None):
        self.params = params
        self.n = n
        self._m = _ops.for_size(n)
        self._accel_limited = math.isfinite(params.max_accel)
        self._trig_yaw = None
        self._trig_cs = None
        self._decay_h = None

    def _trig(self, yaw):
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

    def _deriv(self, yaw, v, omega, v_cmd, w_cmd):
        m, p = self._m, self.params
        c, sn = m.cos(yaw), m.sin(yaw)
        lat = p.d_cen * omega
        dv = p.w_c * (v_cmd - v)
        if self._accel_limited:
            dv = m.clip(dv, -p.max_accel, p.max_accel)
        return v * c - lat * sn, v * sn + lat * c, omega, dv, p.yaw_bandwidth * (w_cmd - omega)

    def clamp_command(self, speed: Num, yaw_rate: Num) -> tuple[Num, Num]:
        m, p = self._m, self.params
        return (m.clip(speed, -p.max_speed, p.max_speed),
                m.clip(yaw_rate, -p.max_yaw_rate, p.max_yaw_rate))

    def step(self, s: RoverState, speed_cmd: Num, yaw_rate_cmd: Num, dt: float) -> RoverState:
        """Advance ``dt`` seconds with the commands (v_ref, omega_ref) held."""
        u, w = self.clamp_command(speed_cmd, yaw_rate_cmd)
        if self._accel_limited:
            return self._step_rk4(s, u, w, dt)
        return self._step_exact(s, u, w, dt)

    def _decays(self, h: float):
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
        c0, s0 = self._trig(s.yaw)
        c1, s1 = self._m.cos(yaw_mid), self._m.sin(yaw_mid)
        c2, s2 = self._trig(yaw_end)
        d = p.d_cen
        lat0, lat1, lat2 = d * s.omega, d * w_mid, d * w_end
        h6 = h / 6.0
        x = s.x + h6 * ((s.v * c0 - lat0 * s0) + 4.0 * (v_mid * c1 - lat1 * s1) + (v_end * c2 - lat2 * s2))
        y = s.y + h6 * ((s.v * s0 + lat0 * c0) + 4.0 * (v_mid * s1 + lat1 * c1) + (v_end * s2 + lat2 * c2))
        return RoverState(x, y, yaw_end, v_end, w_end)

    def _step_rk4(self, s: RoverState, u: Num, w: Num, dt: float) -> RoverState:
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
