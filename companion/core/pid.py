"""The paper's PID baseline (Lee et al. 2024, Section 5), on the raw measurement.

    u_p       = k_P (p_ref - p) + k_I int (p_ref - p) + k_D (p_ref' - p')
    omega_ref = k_P (phi_ref - phi) + k_I int (phi_ref - phi) + k_D (phi_ref' - phi')

with phi_ref = atan2(u_y, u_x) as for PZC (eq. 20), the paper's gains k_P 3.5, k_I 0.5, k_D 0.5,
and the same speed law, limits and anti-windup as the PZC tracker (so the comparison is of the
feedback laws, not of the speed law). p' and phi' are the vehicle's own velocity estimates
(LOCAL_POSITION_NED vx, vy and ATTITUDE yawspeed); phi_ref' is differenced between steps.
There is no filter: the pose the law uses (``estimate``) is the measurement itself.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from . import ops as _ops
from .controllers import MAY_BE_ZERO
from .limits import SPEED_LAWS, Limits, clamp, keep_if, speed_from_up
from .signals import Command, Estimate, Measurement, Num, Reference
from .tracker import raw_estimate


@dataclass(frozen=True)
class PIDGains:
    """The paper's "well-tuned" PID gains (Section 5), tuned there for f_r 0.04 Hz, d_cen 0.
    k_I and k_D may be 0 (a PD or PI law is still one); k_P must be > 0."""

    kp: Num = 3.5
    ki: Num = field(default=0.5, metadata={MAY_BE_ZERO: True})
    kd: Num = field(default=0.5, metadata={MAY_BE_ZERO: True})
    speed_law: str = "projected"

    def __post_init__(self) -> None:
        if self.speed_law not in SPEED_LAWS:
            raise ValueError(f"speed_law must be one of {', '.join(SPEED_LAWS)}, "
                             f"not {self.speed_law!r}")


class PIDTracker:
    """The PID baseline as a :class:`~companion.core.tracker.Tracker`."""

    name = "pid"

    def __init__(self, gains: PIDGains = PIDGains(), limits: Limits = Limits(), n: int | None = None):
        self.gains, self.limits, self.n = gains, limits, n
        self._m = _ops.for_size(n)
        self.reset()

    def reset(self) -> None:
        zero = self._m.zeros(self.n)
        self.t: float | None = None
        self.int_x = self.int_y = self.int_yaw = zero
        self.prev_yaw_ref = zero
        self.estimate: Estimate | None = None

    def step(self, t: float, meas: Measurement, ref: Reference) -> Command:
        m, g = self._m, self.gains
        self.estimate = raw_estimate(meas)
        first = self.t is None
        dt = 0.0 if self.t is None else t - self.t
        self.t = t
        ex, ey = ref.x - meas.x, ref.y - meas.y
        int_x, int_y = self.int_x + ex * dt, self.int_y + ey * dt
        ux = g.kp * ex + g.ki * int_x + g.kd * (ref.vx - meas.vx)
        uy = g.kp * ey + g.ki * int_y + g.kd * (ref.vy - meas.vy)

        yaw_ref = m.atan2(uy, ux)
        yaw_ref_rate = 0.0 if first else m.wrap(yaw_ref - self.prev_yaw_ref) / dt
        self.prev_yaw_ref = yaw_ref
        eyaw = m.wrap(yaw_ref - meas.yaw)
        int_yaw = self.int_yaw + eyaw * dt
        yaw_rate = g.kp * eyaw + g.ki * int_yaw + g.kd * (yaw_ref_rate - meas.yaw_rate)

        norm_up = m.hypot(ux, uy)
        speed = speed_from_up(m, g.speed_law, norm_up, eyaw)
        cmd, speed_free, rate_free = clamp(m, self.limits, speed, yaw_rate, ux, uy, norm_up)
        self.int_x = keep_if(m, speed_free, int_x, self.int_x)
        self.int_y = keep_if(m, speed_free, int_y, self.int_y)
        self.int_yaw = keep_if(m, rate_free, int_yaw, self.int_yaw)
        return cmd


DEFAULT_GAINS = PIDGains()


def build(limits: Limits, n: int | None = None, gains: PIDGains | None = None) -> PIDTracker:
    """The registry's builder (:mod:`companion.core.controllers`): ``gains``, else the
    paper's."""
    return PIDTracker(DEFAULT_GAINS if gains is None else gains, limits, n)
