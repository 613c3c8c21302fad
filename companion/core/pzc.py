"""The PZC PI tracking law of Lee et al. (2024), eqs. (20), (22), (23), (25), with limits.

Position loop, eq. (25):   u_p = K_P p~ + K_I int p~,           p~ = p_ref - p_hat
Heading reference, eq. (20): phi_ref = atan2(u_y, u_x)
Yaw loop, eq. (22):        omega_ref = K_P phi~ + K_I int phi~,  phi~ = wrap(phi_ref - phi_hat)
PZC gains, eq. (23):       K_P = k_dc + lambda_c,  K_I = k_dc * lambda_c

(paper symbols: K_P = k_{P,PZC}, K_I = k_{I,PZC}, k_dc = k_{d,c}, lambda_c = lambda_c.)
Around a pure integrator (p' = u_p + d) the loop is p~'' = -K_P p~' - K_I p~ + d', whose
characteristic polynomial factors as (s + k_dc)(s + lambda_c): the error obeys the first-order
system p~' = -lambda_c p~ + q driven by an excitation q' = -k_dc q + ... (Lemmas 5 and 7,
eqs. (43), (52)). With k_dc large, q dies fast and p~ decays at lambda_c, the objective (4).

Speed law. Eq. (20) sets v_ref = |u_p| (``speed_law="paper"``). That law never slows down for
a heading error: with d_cen = 0 a rover pointing away from u_p drives at full speed the wrong
way while it turns, and on a moving reference it settles into orbits around it. The default,
``speed_law="projected"``, commands the component of u_p along the current heading,

    v_ref = u_x cos(phi_hat) + u_y sin(phi_hat) = |u_p| cos(phi_ref - phi_hat),

which keeps the limit property (21): as phi -> phi_ref, v_ref -> |u_p| and Delta f -> 0. The
rover then never moves against u_p (its velocity along u_p is |u_p| cos^2 >= 0) and backs up
while it turns round instead of circling.

Extensions beyond the paper (all off by default, each measured by ``companion paper-table`` and
chosen by ``companion tune``):

* separate gain pairs for the yaw loop (``k_dc_yaw``, ``lambda_c_yaw``); the paper uses one pair;
* reference-velocity feed-forward ``u_p += p_ref'`` (``velocity_ff``), which makes the error
  dynamics p~' = -(K_P p~ + K_I int p~) exact for a moving reference;
* heading-rate feed-forward ``omega_ref += d/dt heading(p_ref')`` (``heading_rate_ff``);
* reference-acceleration feed-forward ``u_p += tau p_ref''`` (``accel_ff = tau`` seconds), which
  compensates a slow actuator: a first-order lag w_c/(s + w_c) driven by v_ref + p_ref''/w_c
  delivers p_ref' exactly, so tau = 1/w_c is the ideal value for a linear actuator. Because
  p_ref'' has a centripetal part, it also turns phi_ref = atan2(u_p) ahead of the path, leading
  the (equally slow) yaw actuator;
* actuator lead (``lead_tau`` = the actuator's time constant 1/w_c in seconds, ``lead_max_gain``):
  cancels a slow actuator's pole, see :mod:`companion.core.lead`.

Limits: speed and yaw rate are clamped; while either output is clamped its integrator is held
(conditional integration), so nothing winds up in saturation.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from . import ops as _ops
from .filter import FilterGains, PoseFilter
from .lead import ActuatorLead
from .limits import SPEED_LAWS, Limits, clamp, keep_if, speed_from_up
from .signals import Command, Estimate, Measurement, Num, Reference


@dataclass(frozen=True)
class PZCGains:
    """Controller design parameters. Defaults are the paper's Section 5 values (k_dc 5, lambda_c 12).

    ``k_dc_yaw``/``lambda_c_yaw`` of ``None`` mean "same as the position loop" (the paper's form).
    Numeric fields may be numpy arrays in batch simulation; the feed-forward switches may then
    be arrays of 0.0/1.0.
    """

    k_dc: Num = 5.0
    lambda_c: Num = 12.0
    k_dc_yaw: Num | None = None
    lambda_c_yaw: Num | None = None
    velocity_ff: Num = False
    heading_rate_ff: Num = False
    accel_ff: Num = 0.0
    lead_tau: Num = 0.0
    lead_max_gain: Num = 1.0
    speed_law: str = "projected"

    def __post_init__(self):
        if self.speed_law not in SPEED_LAWS:
            raise ValueError(f"speed_law must be one of {SPEED_LAWS}, not {self.speed_law!r}")

    @property
    def kp(self) -> Num:
        """Eq. (23): K_P = k_dc + lambda_c."""
        return self.k_dc + self.lambda_c

    @property
    def ki(self) -> Num:
        """Eq. (23): K_I = k_dc * lambda_c."""
        return self.k_dc * self.lambda_c

    @property
    def kp_yaw(self) -> Num:
        k, lam = self._yaw_pair()
        return k + lam

    @property
    def ki_yaw(self) -> Num:
        k, lam = self._yaw_pair()
        return k * lam

    def _yaw_pair(self):
        k = self.k_dc if self.k_dc_yaw is None else self.k_dc_yaw
        lam = self.lambda_c if self.lambda_c_yaw is None else self.lambda_c_yaw
        return k, lam


def reference_heading_rate(ref: Reference, m=_ops.scalar) -> Num:
    """d/dt atan2(vy, vx) of the reference = (vx ay - vy ax) / |v|^2 (0 where it stands still)."""
    speed2 = ref.vx * ref.vx + ref.vy * ref.vy
    return (ref.vx * ref.ay - ref.vy * ref.ax) / m.maximum(speed2, 1e-6)


class PZCLaw:
    """Eqs. (20), (22), (23), (25) on the filtered pose, with limits and anti-windup."""

    def __init__(self, gains: PZCGains = PZCGains(), limits: Limits = Limits(), n: int | None = None):
        self.gains = gains
        self.limits = limits
        self.n = n
        self._m = _ops.for_size(n)
        self._accel_ff = not _ops.is_plain_zero(gains.accel_ff)   # decided once, off the hot path
        self.reset()

    def reset(self) -> None:
        zero = self._m.zeros(self.n)
        self.t: float | None = None
        self.int_x = self.int_y = self.int_yaw = zero

    def step(self, t: float, est: Estimate, ref: Reference) -> Command:
        m, g, lim = self._m, self.gains, self.limits
        dt = 0.0 if self.t is None else t - self.t
        self.t = t

        ex = ref.x - est.x
        ey = ref.y - est.y
        int_x = self.int_x + ex * dt
        int_y = self.int_y + ey * dt
        ux = g.kp * ex + g.ki * int_x + g.velocity_ff * ref.vx
        uy = g.kp * ey + g.ki * int_y + g.velocity_ff * ref.vy
        if self._accel_ff:
            ux = ux + g.accel_ff * ref.ax
            uy = uy + g.accel_ff * ref.ay

        yaw_ref = m.atan2(uy, ux)
        eyaw = m.wrap(yaw_ref - est.yaw)
        int_yaw = self.int_yaw + eyaw * dt
        yaw_rate = g.kp_yaw * eyaw + g.ki_yaw * int_yaw
        if g.heading_rate_ff is not False:
            yaw_rate = yaw_rate + g.heading_rate_ff * reference_heading_rate(ref, m)

        norm_up = m.hypot(ux, uy)
        speed = speed_from_up(m, g.speed_law, norm_up, eyaw)
        cmd, speed_free, rate_free = clamp(m, lim, speed, yaw_rate, ux, uy, norm_up)
        # Conditional integration: keep the new integrator state only while unsaturated.
        self.int_x = keep_if(m, speed_free, int_x, self.int_x)
        self.int_y = keep_if(m, speed_free, int_y, self.int_y)
        self.int_yaw = keep_if(m, rate_free, int_yaw, self.int_yaw)
        return cmd


class PZCTracker:
    """Measurement -> model-free filter -> PZC law -> command: the paper's Figure 2."""

    name = "pzc"

    def __init__(self, filter_gains: FilterGains = FilterGains(), gains: PZCGains = PZCGains(),
                 limits: Limits = Limits(), n: int | None = None):
        self.filter = PoseFilter(filter_gains, n)
        self.law = PZCLaw(gains, limits, n)
        self.lead = ActuatorLead(gains.lead_tau, gains.lead_max_gain, limits, n)
        self.estimate: Estimate | None = None

    def reset(self) -> None:
        """Forget everything: the next sample re-initialises the filter and the integrators."""
        self.filter = PoseFilter(self.filter.gains, self.filter.n)
        self.law.reset()
        self.lead.reset()
        self.estimate = None

    def step(self, t: float, meas: Measurement, ref: Reference) -> Command:
        self.estimate = self.filter.step(t, meas)
        return self.lead.step(t, self.law.step(t, self.estimate, ref))


def with_paper_speed_law(gains: PZCGains) -> PZCGains:
    """The same gains with the paper's literal v_ref = |u_p| (eq. 20)."""
    return replace(gains, speed_law="paper")
