"""Kanayama's kinematic tracking law: Y. Kanayama, Y. Kimura, F. Miyazaki and T. Noguchi, "A
stable tracking control method for an autonomous mobile robot", ICRA 1990, pp. 384-389.

The paper's symbols: the reference posture q_r = (x_r, y_r, theta_r) moving at the reference
speed v_r and turn rate omega_r; the error posture p_e = (x_e, y_e, theta_e), the reference
seen from the vehicle's own frame,

    x_e =  cos(theta)(x_r - x) + sin(theta)(y_r - y)
    y_e = -sin(theta)(x_r - x) + cos(theta)(y_r - y)
    theta_e = theta_r - theta

and its tracking control rule (K_x in 1/s, K_y in 1/m^2, K_theta in 1/m)

    v     = v_r cos(theta_e) + K_x x_e
    omega = omega_r + v_r (K_y y_e + K_theta sin(theta_e))

v_r and omega_r are feed-forward terms, as the law has them: here v_r = |p_ref'|, theta_r =
atan2(p_ref') and omega_r = d theta_r / dt = (x_r' y_r'' - y_r' x_r'') / |p_ref'|^2, all from the
reference's first and second derivatives. The law assumes the tracked point is the axle's
midpoint; on a rover with d_cen > 0 it steers the axle towards a path drawn for the tracked point.
No filter: the pose the law uses (``estimate``) is the measurement itself.
"""

from __future__ import annotations

from dataclasses import dataclass

from . import ops as _ops
from .limits import Limits, clamp
from .pzc import reference_heading_rate
from .signals import Command, Estimate, Measurement, Num, Reference
from .tracker import raw_estimate


@dataclass(frozen=True)
class KanayamaGains:
    """K_x (1/s), K_y (1/m^2), K_th (1/m); chosen by hand on the paper's f_r 0.04 Hz ellipse
    (its ideal plant: on a real vehicle's lag and limits they limit-cycle, so a fair comparison
    flies gains picked for that vehicle, ``--controller-gains``; benchmarks/kanayama_gains.toml).
    All must be > 0 (the law's Lyapunov proof)."""

    kx: Num = 3.0
    ky: Num = 4.0
    kth: Num = 3.0


class KanayamaTracker:
    """Kanayama's law as a :class:`~companion.core.tracker.Tracker` (stateless but for
    ``estimate``)."""

    name = "kanayama"

    def __init__(self, gains: KanayamaGains = KanayamaGains(), limits: Limits = Limits(),
                 n: int | None = None):
        self.gains, self.limits, self.n = gains, limits, n
        self._m = _ops.for_size(n)
        self.estimate: Estimate | None = None

    def reset(self) -> None:
        self.estimate = None

    def step(self, t: float, meas: Measurement, ref: Reference) -> Command:
        m, g = self._m, self.gains
        self.estimate = raw_estimate(meas)
        c, s = m.cos(meas.yaw), m.sin(meas.yaw)
        dx, dy = ref.x - meas.x, ref.y - meas.y
        ex = c * dx + s * dy                       # x_e
        ey = -s * dx + c * dy                      # y_e
        v_r = m.hypot(ref.vx, ref.vy)              # feed-forward: the reference speed
        eth = m.wrap(m.atan2(ref.vy, ref.vx) - meas.yaw)     # theta_e = theta_r - theta
        speed = v_r * m.cos(eth) + g.kx * ex
        # omega_r (the reference's turn rate) is the feed-forward of the turn-rate channel.
        yaw_rate = reference_heading_rate(ref, m) + v_r * (g.ky * ey + g.kth * m.sin(eth))
        # u_p: the commanded velocity vector, for a velocity-vector autopilot.
        cmd, _, _ = clamp(m, self.limits, speed, yaw_rate, speed * c, speed * s, abs(speed))
        return cmd


DEFAULT_GAINS = KanayamaGains()


def build(limits: Limits, n: int | None = None,
          gains: KanayamaGains | None = None) -> KanayamaTracker:
    """The registry's builder (:mod:`companion.core.controllers`): ``gains``, else the
    defaults."""
    return KanayamaTracker(DEFAULT_GAINS if gains is None else gains, limits, n)
