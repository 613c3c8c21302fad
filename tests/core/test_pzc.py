"""The PZC law (eqs. (20), (22), (23), (25)) against Lemmas 5 and 7, and its limits.

Lemmas 5 and 7: around a pure integrator p' = u_p the PI law with K_P = k_dc + lambda_c and
K_I = k_dc lambda_c factors as (s + k_dc)(s + lambda_c): the error obeys the first-order system
p~' = -lambda_c p~ + q, with the excitation q = p~' + lambda_c p~ decaying at k_dc (eqs. (43),
(52)). We run the law on an exact integrator at 1 kHz and fit both exponents.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from companion.core.angles import wrap
from companion.core.limits import Limits
from companion.core.pzc import PZCGains, PZCLaw, reference_heading_rate
from companion.core.signals import Estimate, Reference


def _estimate(x: float, y: float = 0.0, yaw: float = 0.0) -> Estimate:
    return Estimate(x, y, yaw, 0.0, 0.0, 0.0)


def _integrator_loop(gains: PZCGains, duration: float, rate: float = 1000.0):
    """p' = u_p (x only), reference fixed at x = 1: returns t, p~ and q = p~' + lambda_c p~."""
    law = PZCLaw(gains)
    dt = 1.0 / rate
    x = 0.0
    ts, errs, qs = [], [], []
    for k in range(int(duration * rate)):
        t = k * dt
        cmd = law.step(t, _estimate(x), Reference(1.0, 0.0))
        e = 1.0 - x
        ts.append(t)
        errs.append(e)
        qs.append(-cmd.ux + gains.lambda_c * e)    # p~' = -p' = -u_p for a fixed reference
        x += cmd.ux * dt                            # exact for a held input
    return np.array(ts), np.array(errs), np.array(qs)


def _rate(t, v, t0, t1):
    keep = (t >= t0) & (t <= t1) & (np.abs(v) > 1e-12)
    slope, _ = np.polyfit(t[keep], np.log(np.abs(v[keep])), 1)
    return -slope


@pytest.mark.parametrize("k_dc,lambda_c", [(50.0, 2.0), (40.0, 5.0), (5.0, 12.0)])
def test_integrator_loop_is_first_order_at_lambda_c(k_dc, lambda_c):
    gains = PZCGains(k_dc=k_dc, lambda_c=lambda_c)
    slow = min(k_dc, lambda_c)
    t, err, q = _integrator_loop(gains, duration=10.0 / slow)
    # The excitation q dies at k_dc (eq. 43/52) ...
    assert _rate(t, q, 1.0 / k_dc, 6.0 / k_dc) == pytest.approx(k_dc, rel=0.03)
    # ... after which the error is first order at lambda_c (when lambda_c is the slow root).
    if lambda_c < k_dc:
        assert _rate(t, err, 6.0 / k_dc, 8.0 / lambda_c) == pytest.approx(lambda_c, rel=0.03)
        # and first order means: p~' + lambda_c p~ = q ~ 0 once q has died
        late = t > 8.0 / k_dc
        assert np.max(np.abs(q[late])) < 1e-3 * np.max(np.abs(q))


def test_pzc_gains_are_eq_23():
    g = PZCGains(k_dc=5.0, lambda_c=12.0)
    assert (g.kp, g.ki) == (17.0, 60.0)
    assert (g.kp_yaw, g.ki_yaw) == (17.0, 60.0)          # the paper: one pair for both loops
    g2 = PZCGains(k_dc=5.0, lambda_c=12.0, k_dc_yaw=2.0, lambda_c_yaw=3.0)
    assert (g2.kp_yaw, g2.ki_yaw) == (5.0, 6.0)


def test_heading_reference_is_atan2_of_u_p_and_yaw_error_is_wrapped():
    law = PZCLaw(PZCGains(k_dc=1.0, lambda_c=1.0))
    # Reference behind-left of a rover heading almost +pi: phi_ref = atan2(-0.01, -1) ~ -pi + 0.01,
    # the rover's yaw pi - 0.05; the short way is +0.06 rad (turn left), not -6.2 rad.
    cmd = law.step(0.0, _estimate(0.0, 0.0, math.pi - 0.05), Reference(-1.0, -0.01))
    phi_ref = math.atan2(-0.01, -1.0)
    expected_error = wrap(phi_ref - (math.pi - 0.05))
    assert 0.0 < expected_error < 0.1
    assert cmd.yaw_rate == pytest.approx(2.0 * expected_error)   # K_P = 2, integral still 0
    assert (cmd.ux, cmd.uy) == pytest.approx((-2.0, -0.02))


def test_projected_speed_law_backs_up_rather_than_drives_away():
    # u_p points straight behind the rover: the paper's law drives forward at |u_p|,
    # the projection backs up towards the reference (eq. 20 and its limit property (21)).
    est, ref = _estimate(0.0, 0.0, 0.0), Reference(-1.0, 0.0)
    paper = PZCLaw(PZCGains(k_dc=1.0, lambda_c=1.0, speed_law="paper")).step(0.0, est, ref)
    projected = PZCLaw(PZCGains(k_dc=1.0, lambda_c=1.0)).step(0.0, est, ref)
    assert paper.speed == pytest.approx(2.0)
    assert projected.speed == pytest.approx(-2.0)
    # Aligned with u_p both laws agree: property (21), Delta f -> 0 as phi -> phi_ref.
    est2 = _estimate(0.0, 0.0, 0.0)
    ref2 = Reference(1.0, 0.0)
    a = PZCLaw(PZCGains(speed_law="paper")).step(0.0, est2, ref2).speed
    b = PZCLaw(PZCGains()).step(0.0, est2, ref2).speed
    assert a == pytest.approx(b)


def test_anti_windup_holds_the_integrators_while_saturated():
    law = PZCLaw(PZCGains(k_dc=2.0, lambda_c=1.0), Limits(max_speed=0.5, max_yaw_rate=1.0))
    x, dt = 0.0, 0.01
    peak = 0.0
    for k in range(3000):
        cmd = law.step(k * dt, _estimate(x), Reference(10.0, 0.0))
        assert abs(cmd.speed) <= 0.5 and abs(cmd.yaw_rate) <= 1.0
        assert math.hypot(cmd.ux, cmd.uy) <= 0.5 + 1e-12
        if x < 9.0:
            # Saturated the whole way: the integral must not have grown.
            assert law.int_x == 0.0
        x += cmd.speed * dt
        peak = max(peak, x)
    assert x == pytest.approx(10.0, abs=1e-3)
    assert peak - 10.0 < 0.05          # the linear PI alone overshoots 2 cm; wound up: metres


def test_windup_without_the_rule_would_overshoot():
    # The same loop with the integrator left running (no clamp on the integral) overshoots:
    # evidence that the previous test measures something.
    g = PZCGains(k_dc=2.0, lambda_c=1.0)
    x, integral, dt, peak = 0.0, 0.0, 0.01, 0.0
    for _ in range(3000):
        e = 10.0 - x
        integral += e * dt
        u = max(-0.5, min(0.5, g.kp * e + g.ki * integral))
        x += u * dt
        peak = max(peak, x)
    assert peak - 10.0 > 1.0


def test_reference_heading_rate_of_a_circle():
    w, r = 0.5, 3.0
    t = 1.3
    ref = Reference(r * math.cos(w * t), r * math.sin(w * t), -r * w * math.sin(w * t),
                    r * w * math.cos(w * t), -r * w * w * math.cos(w * t), -r * w * w * math.sin(w * t))
    assert reference_heading_rate(ref) == pytest.approx(w)


def test_accel_feed_forward_cancels_a_first_order_actuator():
    # v_cmd = v_ref + tau a_ref through w_c/(s + w_c) with tau = 1/w_c delivers v_ref exactly.
    w_c, dt = 1.2, 0.001
    law = PZCLaw(PZCGains(k_dc=1e-9, lambda_c=1e-9, velocity_ff=True, accel_ff=1.0 / w_c))
    v, errs = 1.0, []                       # start on the reference speed 1 + 0.5 sin(0)
    for k in range(20000):
        t = k * dt
        v_ref, a_ref = 1.0 + 0.5 * math.sin(t), 0.5 * math.cos(t)
        cmd = law.step(t, _estimate(0.0), Reference(0.0, 0.0, v_ref, 0.0, a_ref, 0.0))
        v += (1.0 - math.exp(-w_c * dt)) * (cmd.ux - v)
        errs.append(abs(v - (1.0 + 0.5 * math.sin(t + dt))))
    assert max(errs[1000:]) < 2e-3


def test_wrap_is_half_open_and_the_same_for_floats_and_arrays():
    from companion.core import ops
    edge = [math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 0.0, 2 * math.pi, 1e-12, -1e-12,
            math.pi + 1e-12, -math.pi + 1e-12, 100.0, -100.0]
    rng = np.random.default_rng(1)
    values = np.concatenate([edge, rng.uniform(-50, 50, 1000)])
    arr = ops.array.wrap(values)
    assert np.all(arr > -math.pi) and np.all(arr <= math.pi)
    assert ops.array.wrap(np.array([math.pi, -math.pi])) == pytest.approx([math.pi, math.pi])
    for v, a in zip(values, arr, strict=True):
        s = ops.scalar.wrap(float(v))
        assert -math.pi < s <= math.pi
        assert s == pytest.approx(wrap(float(v)), abs=1e-12)
        assert math.cos(a - s) == pytest.approx(1.0) and abs(a - s) < 1e-9


# --- Extensions for rate-limited, delayed inner loops (issue 12, item 4) --------------------
#
# Each is off by default and must then be the law as it was, bit for bit; on, each must do on
# the model of the identified ArduPilot rover what pzc.py's docstring claims.

from companion.core import ops as _ops  # noqa: E402
from companion.core.limits import clamp, keep_if, speed_from_up  # noqa: E402
from companion.core.pzc import braking_p  # noqa: E402


class _LawBefore:
    """PZCLaw.step as it was before the extensions (frozen copy), the reference they must
    reproduce when off."""

    def __init__(self, gains, limits=Limits(), n=None):
        self.gains, self.limits, self.n = gains, limits, n
        self._m = _ops.for_size(n)
        self._accel_ff = not _ops.is_plain_zero(gains.accel_ff)
        zero = self._m.zeros(n)
        self.t = None
        self.int_x = self.int_y = self.int_yaw = zero

    def step(self, t, est, ref):
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
        self.int_x = keep_if(m, speed_free, int_x, self.int_x)
        self.int_y = keep_if(m, speed_free, int_y, self.int_y)
        self.int_yaw = keep_if(m, rate_free, int_yaw, self.int_yaw)
        return cmd


def _random_run(law, n, steps=400, seed=0):
    """Drive a law with random poses and a random moving reference; all commands, stacked."""
    rng = np.random.default_rng(seed)
    size = None if n is None else n
    out = []
    t = 0.0
    for _ in range(steps):
        t += rng.choice([0.02, 0.02, 0.02, 0.04])
        g = lambda s=1.0: (rng.normal(0.0, s, size) if n is not None  # noqa: E731
                           else float(rng.normal(0.0, s)))
        est = Estimate(g(2.0), g(2.0), g(3.0), g(), g(), g())
        ref = Reference(g(2.0), g(2.0), g(2.0), g(2.0), g(), g())
        c = law.step(t, est, ref)
        out.append(np.array([c.speed, c.yaw_rate, c.ux, c.uy], dtype=float))
    return np.array(out)


OLD_FORMS = [
    PZCGains(),                                                       # the paper's
    PZCGains(0.7, 0.6, k_dc_yaw=1.5, lambda_c_yaw=1.2, velocity_ff=True, heading_rate_ff=True,
             accel_ff=0.06),
    PZCGains(2.0, 1.0, velocity_ff=True, accel_ff=0.3, speed_law="paper"),
]


@pytest.mark.parametrize("gains", OLD_FORMS)
@pytest.mark.parametrize("limits", [Limits(), Limits(1.5, 0.8)])
def test_extensions_off_are_the_old_law_bit_for_bit(gains, limits):
    # Floats (the live loop) and arrays (batch) alike; defaults and explicit "off" values.
    explicit_off = replace(gains, accel_ff_turn=None, brake_accel=0.0, brake_yaw_accel=0.0)
    for n in (None, 5):
        want = _random_run(_LawBefore(gains, limits, n), n)
        for g in (gains, explicit_off):
            assert np.array_equal(_random_run(PZCLaw(g, limits, n), n), want, equal_nan=True)


def test_extensions_off_in_some_lanes_leave_those_lanes_exact():
    # Batch tuning mixes candidates with and without an extension in one array: a lane with
    # brake 0 and accel_ff_turn == accel_ff must still be the old law exactly.
    n = 4
    base = OLD_FORMS[1]
    old = _random_run(_LawBefore(base, Limits(1.5, 0.8), n), n)
    mixed = replace(base, accel_ff_turn=np.array([0.06, 0.0, 0.06, 0.2]),
                    brake_accel=np.array([0.0, 0.5, 0.0, 0.0]),
                    brake_yaw_accel=np.array([0.0, 0.0, 1.0, 0.0]))
    new = _random_run(PZCLaw(mixed, Limits(1.5, 0.8), n), n)
    assert np.array_equal(new[:, :, 0], old[:, :, 0])             # lane 0: all off
    for lane in (1, 2, 3):                                         # each on: something changes
        assert not np.allclose(new[:, :, lane], old[:, :, lane])


def test_extensions_on_floats_and_arrays_agree():
    g = replace(OLD_FORMS[1], accel_ff_turn=0.0, brake_accel=0.5, brake_yaw_accel=1.5)
    one = _random_run(PZCLaw(g, Limits(1.5, 0.8)), None, seed=3)
    arr = _random_run(PZCLaw(g, Limits(1.5, 0.8), 1), 1, seed=3)
    assert np.allclose(one, arr[:, :, 0], rtol=1e-12, atol=1e-12)


def test_new_fields_reject_negative_values():
    for name in ("accel_ff_turn", "brake_accel", "brake_yaw_accel"):
        with pytest.raises(ValueError, match=name):
            PZCGains(**{name: -0.1})
        with pytest.raises(ValueError, match=name):
            PZCGains(**{name: np.array([0.1, -0.1])})


def test_braking_p_is_the_sqrt_controller():
    kp, alpha = 3.0, 2.0
    knee = alpha / kp ** 2
    m = _ops.scalar
    # linear inside the knee, the braking curve beyond, value and slope continuous at the knee
    assert braking_p(m, kp, alpha, 0.5 * knee) == (pytest.approx(kp * 0.5 * knee), False)
    below, _ = braking_p(m, kp, alpha, knee * (1 - 1e-7))
    above, beyond = braking_p(m, kp, alpha, knee * (1 + 1e-7))
    assert beyond and above == pytest.approx(below, rel=1e-6)
    slope = (braking_p(m, kp, alpha, knee * 1.001)[0] - above) / (knee * 0.001)
    assert slope == pytest.approx(kp, rel=2e-3)
    # beyond: a rate from which braking at alpha stops within the error (ends at e = 0 with the
    # linear zone's last alpha / (2 kp^2) to spare), and it grows like sqrt, not linearly
    for e in (0.5, 1.0, 3.0):
        rate, beyond = braking_p(m, kp, alpha, e)
        assert beyond and rate ** 2 / (2 * alpha) == pytest.approx(e - knee / 2)
        assert rate < kp * e
    # alpha 0 (off) and infinity: linear everywhere, in arrays too
    for a in (0.0, math.inf):
        assert braking_p(m, kp, a, 50.0) == (pytest.approx(kp * 50.0), False)
    rate, beyond = braking_p(_ops.array, kp, np.array([0.0, alpha]), np.array([3.0, 3.0]))
    assert rate[0] == pytest.approx(9.0) and not beyond[0] and beyond[1]
    assert rate[1] == pytest.approx(math.sqrt(2 * alpha * (3.0 - knee / 2)))


def test_braking_holds_the_integrators_beyond_the_linear_zone():
    # Yaw error 2 rad (knee 0.22 rad): the yaw integrator must not move; the position error
    # 3 m (knee 0.5 m at K_P 1, 0.5 m/s^2) holds the position integrators likewise.
    g = PZCGains(0.5, 0.5, k_dc_yaw=1.5, lambda_c_yaw=1.5, brake_accel=0.5, brake_yaw_accel=2.0)
    law = PZCLaw(g)
    est = Estimate(0.0, 0.0, 2.0, 0.0, 0.0, 0.0)
    for k in range(50):
        cmd = law.step(0.02 * k, est, Reference(3.0, 0.0))
    assert (law.int_x, law.int_y, law.int_yaw) == (0.0, 0.0, 0.0)
    assert abs(cmd.yaw_rate) == pytest.approx(math.sqrt(2 * 2.0 * (2.0 - 2.0 / 9 / 2)))
    # near the reference (inside both knees) they integrate as eq. (22)/(25)
    law.reset()
    est = Estimate(2.9, 0.0, 0.05, 0.0, 0.0, 0.0)
    for k in range(50):
        law.step(0.02 * k, est, Reference(3.0, 0.0))
    assert law.int_x == pytest.approx(0.1 * 49 * 0.02)
    assert law.int_yaw == pytest.approx(-0.05 * 49 * 0.02)



def test_brake_integrate_lets_the_position_integrators_run_out_to_that_many_knees():
    # knee 0.5 m (K_P 1, 0.5 m/s^2): 1.5 m is three knees out, 3 m six
    g = PZCGains(0.5, 0.5, brake_accel=0.5)

    def int_x(knees: float, error: float, n: int | None = None) -> float:
        law = PZCLaw(replace(g, brake_integrate=knees), n=n)
        for k in range(50):
            law.step(0.02 * k, Estimate(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), Reference(error, 0.0))
        return law.int_x
    assert int_x(1.0, 1.5) == 0.0                                  # the default: held
    assert int_x(4.0, 1.5) == pytest.approx(1.5 * 49 * 0.02)       # within four knees
    assert int_x(4.0, 3.0) == 0.0                                  # beyond them: held
    # the P term is the braking curve's either way
    law = PZCLaw(replace(g, brake_integrate=4.0))
    cmd = law.step(0.0, Estimate(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), Reference(1.5, 0.0))
    assert cmd.ux == pytest.approx(math.sqrt(2 * 0.5 * (1.5 - 0.25)))
    # lanes of an array: each its own zone
    law = PZCLaw(replace(g, brake_integrate=np.array([1.0, 4.0])), n=2)
    for k in range(50):
        law.step(0.02 * k, Estimate(*(np.zeros(2),) * 6), Reference(np.full(2, 1.5), np.zeros(2)))
    assert law.int_x == pytest.approx([0.0, 1.5 * 49 * 0.02])
    with pytest.raises(ValueError, match="brake_integrate"):
        PZCGains(brake_integrate=0.5)


def test_the_approach_cone_holds_u_p_within_its_angle_of_the_reference_direction():
    # reference east at 1 m/s, K_P 1 (K_I 0.25): 0.2 m to the side is 11 deg off, well inside a
    # 30 deg cone (untouched); 3 m to the side would be 72 deg off: held at 30 deg, |u . t| kept
    g = PZCGains(0.5, 0.5, velocity_ff=True)
    cone = replace(g, approach_cone=math.radians(30.0))
    est = Estimate(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def step(gains: PZCGains, side: float, speed: float = 1.0, steps: int = 1) -> tuple:
        law = PZCLaw(gains)
        for k in range(steps):
            cmd = law.step(0.02 * k, est, Reference(0.0, side, speed, 0.0))
        return cmd.ux, cmd.uy, law.int_y

    assert step(cone, 0.2) == step(g, 0.2)
    ux, uy, _ = step(cone, 3.0)
    assert ux == pytest.approx(1.0) and uy == pytest.approx(math.tan(math.radians(30.0)))
    ux, uy, _ = step(cone, -3.0)
    assert uy == pytest.approx(-math.tan(math.radians(30.0)))
    # while it acts the position integrators hold (as the progress floor's do)
    assert step(cone, 3.0, steps=20)[2] == 0.0 and step(g, 3.0, steps=20)[2] > 0.0
    # a rover far ahead (u_p . t below half the reference speed) still gets half of it to turn on
    law = PZCLaw(cone)
    cmd = law.step(0.0, Estimate(5.0, 0.0, 0.0, 0.0, 0.0, 0.0), Reference(0.0, 3.0, 1.0, 0.0))
    assert abs(cmd.uy) == pytest.approx(0.5 * math.tan(math.radians(30.0)))
    # a reference standing still: no direction, no cone
    assert step(cone, 3.0, speed=0.0) == step(g, 3.0, speed=0.0)
    # array lanes: each its own cone (0: none)
    law = PZCLaw(replace(g, approach_cone=np.array([0.0, math.radians(30.0)])), n=2)
    cmd = law.step(0.0, Estimate(*(np.zeros(2),) * 6),
                   Reference(np.zeros(2), np.full(2, 3.0), np.ones(2), np.zeros(2)))
    assert cmd.uy == pytest.approx([step(g, 3.0)[1], math.tan(math.radians(30.0))])
    with pytest.raises(ValueError, match="approach_cone"):
        PZCGains(approach_cone=math.pi / 2)
    with pytest.raises(ValueError, match="approach_cone"):
        PZCGains(approach_cone=-0.1)


def test_split_feed_forward_previews_speed_without_turning_the_heading():
    # A circle at 2 m/s speeding up at 0.5 m/s^2: accel_ff turns u_p into the curve by
    # atan(tau v w / (v + tau a_t)), accel_ff_turn = 0 keeps u_p along p_ref' (lengthened by
    # tau a_t), accel_ff_turn = accel_ff is the unsplit law.
    w, tau = 0.5, 0.2
    v, a_t = 2.0, 0.5
    ref = Reference(0.0, 0.0, v, 0.0, a_t, v * w)                  # heading +x, turning left
    est = _estimate(0.0)
    kw = dict(k_dc=1.0, lambda_c=1.0, velocity_ff=True, accel_ff=tau)
    whole = PZCLaw(PZCGains(**kw)).step(0.0, est, ref)
    split = PZCLaw(PZCGains(**kw, accel_ff_turn=0.0)).step(0.0, est, ref)
    same = PZCLaw(PZCGains(**kw, accel_ff_turn=tau)).step(0.0, est, ref)
    assert (whole.ux, whole.uy) == pytest.approx((v + tau * a_t, tau * v * w))
    assert (split.ux, split.uy) == pytest.approx((v + tau * a_t, 0.0), abs=1e-12)
    assert (same.ux, same.uy) == pytest.approx((whole.ux, whole.uy), abs=1e-12)
    # a reference starting from rest: all of p_ref'' is along the path, none of it is dropped
    still = PZCLaw(PZCGains(**kw, accel_ff_turn=0.0)).step(0.0, est, Reference(0, 0, 0, 0, 0.5, 0))
    assert (still.ux, still.uy) == pytest.approx((tau * 0.5, 0.0))


# The rover identified from an ArduPilot Rover SITL log (rover-skid, stock parameters), as in
# /work/exp/id_try.toml: speed 0.14 s delay + 0.08 s lag, turn rate 0.045 + 0.017 s.
from companion.sim.plant import RoverParams  # noqa: E402

ARDUPILOT_SKID = RoverParams(
    w_c=1 / 0.081877, w_c_yaw=1 / 0.0166667, max_speed=3.08332, max_yaw_rate=2.0944,
    max_accel=0.992639, max_decel=1.04054, max_yaw_accel=2.07679, max_yaw_decel=1.8737,
    speed_delay=0.137804, yaw_delay=0.0448846, turn_speed_coupling=0.0674473)
# What the robust tuner chose for it without the extensions (k_df 1238, lambda_f 242).
TUNED_BEFORE = PZCGains(0.691, 0.578, velocity_ff=True, heading_rate_ff=True, accel_ff=0.0585)


def _fly(lanes: list[PZCGains], f_r: float, vehicle: RoverParams = ARDUPILOT_SKID):
    """Each gain set on the vehicle at 40 Hz on ArduPilot's ticks with EKF-like noise, one
    batch: (steady RMS, share of the second half at the yaw-rate limit) per lane."""
    from dataclasses import fields

    from companion.core.filter import FilterGains
    from companion.core.pzc import PZCTracker
    from companion.core.trajectory import Ellipse
    from companion.sim.batch import SimConfig, simulate
    n = len(lanes)
    stacked = {}
    for f in fields(PZCGains):
        values = [getattr(g, f.name) for g in lanes]
        if f.name == "speed_law":
            stacked[f.name] = values[0]
            continue
        if f.name in ("k_dc_yaw", "lambda_c_yaw"):
            values = [getattr(g, f.name[:-4]) if v is None else v for g, v in zip(lanes, values, strict=True)]
        if f.name == "accel_ff_turn":
            values = [g.accel_ff if v is None else v for g, v in zip(lanes, values, strict=True)]
        stacked[f.name] = np.array(values, dtype=float)
    tracker = PZCTracker(FilterGains(1237.8, 242.1), PZCGains(**stacked),
                         Limits(3.08332, 2.0944), n=n)
    sim = SimConfig(duration=60.0, control_rate=40.0, max_plant_dt=0.01, tick=0.02,
                    noise_pos=0.005, noise_yaw=0.002, seed=1)
    params = vehicle.with_(d_cen=np.zeros(n))
    with np.errstate(all="ignore"):
        r = simulate(tracker, params, Ellipse.paper(np.full(n, f_r)), n, sim)
    return np.asarray(r.steady_rms), np.asarray(r.yaw_at_limit)


def test_split_preview_tracks_the_speed_channel_delay_and_lag():
    # 0.08 Hz: the speed lags ~0.22 s behind its setpoint. Previewing all of p_ref'' by 0.22 s
    # cuts the turns (worse than the tuned 0.06 s); previewing only its along-path part removes
    # the lag (model: 0.125 -> 0.054 m).
    rms, at_limit = _fly([TUNED_BEFORE, replace(TUNED_BEFORE, accel_ff=0.22),
                          replace(TUNED_BEFORE, accel_ff=0.22, accel_ff_turn=0.0)], 0.08)
    assert 0.1 < rms[0] < 0.16
    assert rms[1] > 1.3 * rms[0]
    assert rms[2] < 0.07 and rms[2] < 0.55 * rms[0]
    assert at_limit.max() == 0.0


def test_yaw_braking_curve_stops_the_limit_cycle_on_a_slower_neighbour():
    # Firmer yaw gains on the identified rover's slow corner (lags x1.3, accel limits x0.85, one
    # telemetry sample later): the linear yaw PI meets the turn-rate accel limit as a relay and
    # limit-cycles; the braking curve with the integrator held beyond it does not.
    slow = ARDUPILOT_SKID.with_(
        w_c=ARDUPILOT_SKID.w_c / 1.3, w_c_yaw=ARDUPILOT_SKID.w_c_yaw / 1.3,
        max_accel=0.992639 * 0.85, max_decel=1.04054 * 0.85, max_yaw_accel=2.07679 * 0.85,
        max_yaw_decel=1.8737 * 0.85, speed_delay=0.137804 + 0.025, yaw_delay=0.0448846 + 0.025)
    firm = PZCGains(0.3, 0.3, k_dc_yaw=2.0, lambda_c_yaw=2.0, velocity_ff=True,
                    heading_rate_ff=True, accel_ff=0.22, accel_ff_turn=0.0)
    rms, at_limit = _fly([firm, replace(firm, brake_yaw_accel=2.0)], 0.04, slow)
    assert at_limit[0] > 0.3 and rms[0] > 1.0                       # the limit cycle (3 m)
    assert at_limit[1] < 0.01 and rms[1] < 0.03                     # held (1.3 cm)


def test_braking_curves_shorten_the_chase_when_the_reference_outruns_the_rover():
    # 0.12 Hz: the reference peaks at 4.77 m/s, the rover tops out at 3.08. The yaw braking
    # curve lets firmer yaw gains run without a limit cycle, and the position braking curve
    # (with its integrators held) shortens the chase (model: 1.98 before, ~1.6 and ~1.5 m).
    firm = PZCGains(0.5, 0.5, k_dc_yaw=1.5, lambda_c_yaw=1.5, velocity_ff=True,
                    heading_rate_ff=True, accel_ff=0.22, accel_ff_turn=0.0, brake_yaw_accel=2.0)
    rms, at_limit = _fly([TUNED_BEFORE, firm, replace(firm, brake_accel=0.5)], 0.12)
    assert rms[0] > 1.85
    assert rms[1] < 0.9 * rms[0]
    assert rms[2] < 0.96 * rms[1]
    assert at_limit.max() < 0.05
