"""The PZC law (eqs. (20), (22), (23), (25)) against Lemmas 5 and 7, and its limits.

Lemmas 5 and 7: around a pure integrator p' = u_p the PI law with K_P = k_dc + lambda_c and
K_I = k_dc lambda_c factors as (s + k_dc)(s + lambda_c): the error obeys the first-order system
p~' = -lambda_c p~ + q, with the excitation q = p~' + lambda_c p~ decaying at k_dc (eqs. (43),
(52)). We run the law on an exact integrator at 1 kHz and fit both exponents.
"""

from __future__ import annotations

import math

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
    for v, a in zip(values, arr):
        s = ops.scalar.wrap(float(v))
        assert -math.pi < s <= math.pi
        assert s == pytest.approx(wrap(float(v)), abs=1e-12)
        assert math.cos(a - s) == pytest.approx(1.0) and abs(a - s) < 1e-9
