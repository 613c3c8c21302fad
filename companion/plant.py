"""The rover the paper simulates (Section 5): eqs. (1)-(2) with first-order actuators.

    x'   = v cos(phi) - d_cen omega sin(phi)          eq. (1), p = [x, y]
    y'   = v sin(phi) + d_cen omega cos(phi)
    phi' = omega                                      eq. (2)
    v'     = w_c     (v_ref - v)       (clipped to +-max_accel)
    omega' = w_c_yaw (omega_ref - omega)

``d_cen`` is the paper's distance between the centre of mass (the tracked point p) and the wheel
axle; ``w_c`` the paper's actuator bandwidth omega_c (k_c). The commands are clamped to the
vehicle's top speed and turn rate. Integration is classic RK4 with the commands held over the
step. Works on floats (one rover, e.g. the bundled MAVLink plant) or arrays (batch simulation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from . import ops as _ops
from .signals import Measurement, Num


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

    def velocity(self, s: RoverState) -> tuple[Num, Num]:
        """Eq. (1): the tracked point's velocity (what LOCAL_POSITION_NED reports as vx, vy)."""
        m, d = self._m, self.params.d_cen
        c, sn = m.cos(s.yaw), m.sin(s.yaw)
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
        """Advance ``dt`` seconds with the commands (v_ref, omega_ref) held (RK4)."""
        u, w = self.clamp_command(speed_cmd, yaw_rate_cmd)
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
