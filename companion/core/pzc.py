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

Speed law. ``speed_law="paper"``: eq. (20), v_ref = |u_p|. ``speed_law="projected"`` (the
default): the component of u_p along the heading, which keeps the limit property (21),

    v_ref = u_x cos(phi_hat) + u_y sin(phi_hat) = |u_p| cos(phi_ref - phi_hat).

Extensions beyond the paper, each off by default (the paper's law exactly) and chosen by a tuner
(``companion tune``; the robust tuner :mod:`companion.sim.robust` for an identified vehicle):

* ``k_dc_yaw``, ``lambda_c_yaw``: the yaw loop's own PZC pair in eq. (23);
* ``velocity_ff``:     u_p += p_ref'
* ``heading_rate_ff``: omega_ref += d/dt heading(p_ref')
* ``accel_ff`` = tau (s): u_p += tau p_ref''; with ``accel_ff_turn`` = tau_n (s) the part normal
  to p_ref' takes its own time:
      u_p += tau p_ref'' + (tau_n - tau) a_n,   a_n = (d/dt heading(p_ref')) J p_ref'
  (J: rotation by +90 deg);
* ``brake_accel`` (m/s^2, position loop on |p~|), ``brake_yaw_accel`` = alpha (rad/s^2, yaw loop):
  the P term becomes ArduPilot's square-root controller, and the integrator is held beyond its
  linear zone:
      P(e) = K_P e                                            for |e| <= alpha / K_P^2
           = sign(e) sqrt(2 alpha (|e| - alpha / (2 K_P^2)))  beyond;
  with ``brake_integrate`` = n (>= 1, knees) the position integrators integrate on beyond the
  knee out to |p~| <= n alpha / K_P^2 and hold only further out;
* ``min_progress`` = gamma: with t = p_ref' / |p_ref'|, u_p += max(0, gamma |p_ref'| - u_p . t) t,
  the position integrators held while it acts (nothing changes where |p_ref'| = 0);
* ``approach_cone`` = chi (rad, below pi/2): u_p's part across the reference's direction t is
  held within the cone about it, |u_p . n| <= tan(chi) max(u_p . t, |p_ref'| / 2) (n = J t), the
  position integrators held while it acts (nothing changes where |p_ref'| = 0). A rover that
  steers along u_p (PX4) cannot reverse a velocity across the path faster than it turns; without
  the cone a metre's error sends it across at right angles and over the path, into a swing;
* ``lead_tau``, ``lead_max_gain``: the actuator lead of :mod:`companion.core.lead`;
* ``course_tau`` (s): the law steers the course over ground, phi-hat + beta-hat, beta-hat the
  angle from the heading to the filtered pose's displacement, summed with forgetting time
  ``course_tau`` (:mod:`companion.core.course`);
* ``predict_s`` = d (s), for a speed loop with a pure delay d: the speed comes from the law run
  on the pose the speed commands of the last d seconds lead to against the reference d ahead,
  the turn rate from the law run on the present (:mod:`companion.core.predict`);
* ``cancel_overshoot`` = g, ``cancel_overshoot_s`` = tau (s), for a speed loop that overshoots
  (the vehicle model's ``speed_overshoot``): the speed sent through the exact inverse of that
  overshoot, last (:mod:`companion.core.overshoot`).

Limits: speed and yaw rate are clamped; while either output is clamped its integrator is held
(conditional integration), so nothing winds up in saturation.

Why each extension exists, what it measured and what was tried and not kept: the design note
docs/design/pzc-extensions.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from . import ops as _ops
from .course import CourseCorrection
from .filter import FilterGains, PoseFilter
from .lead import ActuatorLead
from .limits import SPEED_LAWS, Limits, clamp, clip_yaw_rate, keep_if, speed_from_up
from .overshoot import OvershootCancel
from .predict import DelayPrediction
from .signals import Command, Estimate, Measurement, Num, Reference


@dataclass(frozen=True)
class PZCGains:
    """Controller design parameters. Defaults are the paper's Section 5 values (k_dc 5, lambda_c 12).

    ``k_dc_yaw``/``lambda_c_yaw`` of ``None`` mean "same as the position loop" (the paper's form).
    Numeric fields may be numpy arrays in batch simulation; the feed-forward switches may then
    be arrays of 0.0/1.0. ``accel_ff_turn`` (s; ``None``: as ``accel_ff``), ``brake_accel``
    (m/s^2) and ``brake_yaw_accel`` (rad/s^2; 0: off) are the extensions for rate-limited,
    delayed inner loops described in the module docstring; ``brake_integrate`` (knees, 1: hold
    at the knee) how far past the position braking curve's knee its integrators still run.
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
    accel_ff_turn: Num | None = None
    brake_accel: Num = 0.0
    brake_yaw_accel: Num = 0.0
    min_progress: Num = 0.0
    course_tau: Num = 0.0
    brake_integrate: Num = 1.0
    approach_cone: Num = 0.0
    predict_s: Num = 0.0
    cancel_overshoot: Num = 0.0
    cancel_overshoot_s: Num = 1.0

    def __post_init__(self) -> None:
        if self.speed_law not in SPEED_LAWS:
            raise ValueError(f"speed_law must be one of {SPEED_LAWS}, not {self.speed_law!r}")
        for name in ("accel_ff_turn", "brake_accel", "brake_yaw_accel", "min_progress",
                     "course_tau", "approach_cone", "predict_s", "cancel_overshoot"):
            value = getattr(self, name)
            if value is not None and _any_negative(value):
                raise ValueError(f"{name} must be >= 0, not {value!r}")
        if _any_negative(self.brake_integrate - 1.0):
            raise ValueError(f"brake_integrate must be >= 1 (knees), not {self.brake_integrate!r}")
        if _any_negative(0.5 * math.pi - 1e-9 - self.approach_cone):
            raise ValueError(f"approach_cone must be below pi/2 rad, not {self.approach_cone!r}")
        if _any_negative(self.cancel_overshoot_s):
            raise ValueError(f"cancel_overshoot_s must be >= 0 s, not {self.cancel_overshoot_s!r}")

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

    def _yaw_pair(self) -> tuple[Num, Num]:
        k = self.k_dc if self.k_dc_yaw is None else self.k_dc_yaw
        lam = self.lambda_c if self.lambda_c_yaw is None else self.lambda_c_yaw
        return k, lam


def _any_negative(value: Num) -> bool:
    try:
        return bool((value < 0).any())
    except AttributeError:
        return value < 0


def braking_p(m: _ops.Ops, kp: Num, alpha: Num, err_abs: Num) -> tuple[Num, Num]:
    """The proportional demand for an error magnitude ``err_abs`` (>= 0) under an acceleration
    limit ``alpha``: ``(K_P |e|, False)`` in the linear zone |e| <= alpha / K_P^2, else
    ``(sqrt(2 alpha (|e| - alpha / (2 K_P^2))), True)`` (ArduPilot's ``sqrt_controller``): the
    rate from which decelerating at alpha ends at e = 0. Value and slope are continuous at the
    knee. ``alpha`` 0 means no limit (always linear); it may be an array with zeros."""
    if m is _ops.scalar:                       # one vehicle: plain branches, no where()
        if not 0.0 < alpha < math.inf:
            return kp * err_abs, False
        linear = alpha / (kp * kp)
        if err_abs <= linear:
            return kp * err_abs, False
        return math.sqrt(2.0 * alpha * (err_abs - 0.5 * linear)), True
    a = m.where(alpha > 0, m.minimum(alpha, 1e300), 1e300)   # 0 / inf: a knee never reached
    linear = a / (kp * kp)
    beyond = err_abs > linear
    root = m.sqrt(2.0 * a * m.maximum(err_abs - 0.5 * linear, 0.0))
    return m.where(beyond, root, kp * err_abs), beyond


def reference_heading_rate(ref: Reference, m: _ops.Ops = _ops.scalar) -> Num:
    """d/dt atan2(vy, vx) of the reference = (vx ay - vy ax) / |v|^2 (0 where it stands still)."""
    speed2 = ref.vx * ref.vx + ref.vy * ref.vy
    return (ref.vx * ref.ay - ref.vy * ref.ax) / m.maximum(speed2, 1e-6)


def reference_direction(ref: Reference, m: _ops.Ops = _ops.scalar) -> tuple[Num, Num, Num]:
    """|p_ref'| and the unit vector t = p_ref' / |p_ref'| (arbitrary where |p_ref'| = 0: the
    callers act only where it moves)."""
    speed = m.hypot(ref.vx, ref.vy)
    safe = m.maximum(speed, 1e-6)
    return speed, ref.vx / safe, ref.vy / safe


class PZCLaw:
    """Eqs. (20), (22), (23), (25) on the filtered pose, with limits and anti-windup."""

    def __init__(self, gains: PZCGains = PZCGains(), limits: Limits = Limits(), n: int | None = None):
        self.gains = gains
        self.limits = limits
        self.n = n
        self._m = _ops.for_size(n)
        # Which optional terms run is decided once, off the hot path.
        self._split_ff = gains.accel_ff_turn is not None
        self._accel_ff = not _ops.is_plain_zero(gains.accel_ff) or (
            self._split_ff and not _ops.is_plain_zero(gains.accel_ff_turn))
        self._brake = not _ops.is_plain_zero(gains.brake_accel)
        self._brake_yaw = not _ops.is_plain_zero(gains.brake_yaw_accel)
        self._brake_zone = not (isinstance(gains.brake_integrate, (int, float))
                                and gains.brake_integrate <= 1.0)
        self._progress = not _ops.is_plain_zero(gains.min_progress)
        self._cone = not _ops.is_plain_zero(gains.approach_cone)
        # tan(chi); a lane of 0 (no cone) an unbounded one
        self._cone_tan = (self._m.where(gains.approach_cone > 0, self._m.tan(gains.approach_cone),
                                        math.inf) if self._cone else math.inf)
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
        kp = g.kp
        if self._brake:
            # Braking curve on |p~|, direction kept; integrators held beyond the linear zone.
            err = m.hypot(ex, ey)
            demand, beyond = braking_p(m, kp, g.brake_accel, err)
            if beyond is not False:
                kp = m.where(beyond, demand / m.maximum(err, 1e-12), kp)
                hold = beyond
                if self._brake_zone:
                    # integrate on out to brake_integrate knees: a steady offset there (a
                    # speed loop that over-drives) is the integrator's to take back
                    hold = beyond & (err > g.brake_integrate * g.brake_accel / (g.kp * g.kp))
                int_x = m.where(hold, self.int_x, int_x)
                int_y = m.where(hold, self.int_y, int_y)
        ux = kp * ex + g.ki * int_x + g.velocity_ff * ref.vx
        uy = kp * ey + g.ki * int_y + g.velocity_ff * ref.vy
        heading_rate = None
        if self._accel_ff:
            ux = ux + g.accel_ff * ref.ax
            uy = uy + g.accel_ff * ref.ay
            if self._split_ff:
                # The normal part a_n = heading rate * J p_ref' gets its own preview time.
                heading_rate = reference_heading_rate(ref, m)
                turn = (g.accel_ff_turn - g.accel_ff) * heading_rate
                ux = ux - turn * ref.vy
                uy = uy + turn * ref.vx

        if self._progress or self._cone:
            ref_speed, tx, ty = reference_direction(ref, m)     # both act along/across it
        if self._progress:
            # Progress floor: u_p's component along the reference's direction >= gamma |p_ref'|.
            moving = ref_speed > 1e-6
            lift = m.maximum(g.min_progress * ref_speed - (ux * tx + uy * ty), 0.0)
            lifting = moving & (lift > 0) if m is not _ops.scalar else (moving and lift > 0)
            lift = m.where(lifting, lift, 0.0)
            ux = ux + lift * tx
            uy = uy + lift * ty
            int_x = m.where(lifting, self.int_x, int_x)
            int_y = m.where(lifting, self.int_y, int_y)

        if self._cone:
            ux, uy, held = self._in_cone(ref_speed, tx, ty, ux, uy)
            int_x = m.where(held, self.int_x, int_x)
            int_y = m.where(held, self.int_y, int_y)

        yaw_ref = m.atan2(uy, ux)
        eyaw = m.wrap(yaw_ref - est.yaw)
        int_yaw = self.int_yaw + eyaw * dt
        if self._brake_yaw:
            demand, beyond = braking_p(m, g.kp_yaw, g.brake_yaw_accel, abs(eyaw))
            if beyond is not False:
                int_yaw = m.where(beyond, self.int_yaw, int_yaw)
            yaw_rate = m.where(eyaw < 0, -demand, demand) + g.ki_yaw * int_yaw
        else:
            yaw_rate = g.kp_yaw * eyaw + g.ki_yaw * int_yaw
        if g.heading_rate_ff is not False:
            if heading_rate is None:
                heading_rate = reference_heading_rate(ref, m)
            yaw_rate = yaw_rate + g.heading_rate_ff * heading_rate

        norm_up = m.hypot(ux, uy)
        speed = speed_from_up(m, g.speed_law, norm_up, eyaw)
        cmd, speed_free, rate_free = clamp(m, lim, speed, yaw_rate, ux, uy, norm_up)
        # Conditional integration: keep the new integrator state only while unsaturated.
        self.int_x = keep_if(m, speed_free, int_x, self.int_x)
        self.int_y = keep_if(m, speed_free, int_y, self.int_y)
        self.int_yaw = keep_if(m, rate_free, int_yaw, self.int_yaw)
        return cmd

    def _in_cone(self, ref_speed: Num, tx: Num, ty: Num, ux: Num, uy: Num
                 ) -> tuple[Num, Num, Num]:
        """u_p with its part across the reference's direction t = (tx, ty) held within
        ``approach_cone`` (module docstring), and where that acted."""
        m = self._m
        along, across = ux * tx + uy * ty, uy * tx - ux * ty
        cap = self._cone_tan * m.maximum(along, 0.5 * ref_speed)
        acting = (ref_speed > 1e-6) & (abs(across) > cap)
        across = m.where(acting, m.clip(across, -cap, cap), across)
        return (m.where(acting, along * tx - across * ty, ux),
                m.where(acting, along * ty + across * tx, uy), acting)


class PZCTracker:
    """Measurement -> model-free filter -> PZC law -> command: the paper's Figure 2 (with the
    course correction between filter and law when ``course_tau`` > 0)."""

    name = "pzc"

    def __init__(self, filter_gains: FilterGains = FilterGains(), gains: PZCGains = PZCGains(),
                 limits: Limits = Limits(), n: int | None = None):
        self._m = _ops.for_size(n)
        self.filter = PoseFilter(filter_gains, n)
        self.law = PZCLaw(gains, limits, n)
        self.course = CourseCorrection(gains.course_tau, n)
        self.lead = ActuatorLead(gains.lead_tau, gains.lead_max_gain, limits, n)
        self.predict = DelayPrediction(gains.predict_s, n)
        # the speed's law, d ahead (its own integrators); None without a delay to predict
        self.law_ahead = PZCLaw(gains, limits, n) if self.predict.active else None
        self.cancel = OvershootCancel(gains.cancel_overshoot, gains.cancel_overshoot_s, limits, n)
        self.estimate: Estimate | None = None

    def reset(self) -> None:
        """Forget everything: the next sample re-initialises the filter and the integrators."""
        self.filter = PoseFilter(self.filter.gains, self.filter.n)
        self.law.reset()
        self.course.reset()
        self.lead.reset()
        self.predict.reset()
        if self.law_ahead is not None:
            self.law_ahead.reset()
        self.cancel.reset()
        self.estimate = None

    def step(self, t: float, meas: Measurement, ref: Reference) -> Command:
        self.estimate = self.filter.step(t, meas)
        steered = self.course.step(t, self.estimate)
        cmd = self.law.step(t, steered, ref)
        if self.law_ahead is not None:
            # The speed lands d late, the turn rate at once: each from the law that sees the
            # time it acts at (one law on the predicted pose steered the heading d early and
            # cut the corners: docs/design/pzc-extensions.md).
            ahead, ref_ahead = self.predict.step(t, steered, ref)
            fore = self.law_ahead.step(t, ahead, ref_ahead)
            rate = clip_yaw_rate(self._m, self.law.limits, fore.speed, cmd.yaw_rate)
            cmd = Command(fore.speed, rate, fore.ux, fore.uy)
        cmd = self.lead.step(t, cmd)
        self.predict.sent(t, cmd)        # what the vehicle will drive: the overshoot's undone
        return self.cancel.step(t, cmd)


def with_paper_speed_law(gains: PZCGains) -> PZCGains:
    """The same gains with the paper's literal v_ref = |u_p| (eq. 20)."""
    return replace(gains, speed_law="paper")


DEFAULT_GAINS = None   # for the registry: pzc flies the filter + PZC gains it is given


def build(limits: Limits, n: int | None = None, filter_gains: FilterGains | None = None,
          pzc_gains: PZCGains | None = None) -> PZCTracker:
    """The registry's builder (:mod:`companion.core.controllers`); ``None`` gains are the
    paper's (Section 5)."""
    return PZCTracker(FilterGains() if filter_gains is None else filter_gains,
                      PZCGains() if pzc_gains is None else pzc_gains, limits, n)
