"""The model-free filter (eqs. (7)-(9), (12)-(14)) against the paper's Lemmas 2 and 4.

Lemmas 2 and 4: the filtering error e_f = q - q_hat obeys e_f' = -lambda_f e_f + d_f with the
disturbance d_f dying at k_df, so once d_f is gone the error decays at exactly lambda_f. We fit
that exponent from the filter's own output, at the paper's 1 kHz and at a MAVLink-like 40 Hz.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.core.angles import wrap
from companion.core.filter import FilterGains, PoseFilter, transition
from companion.core.signals import Measurement


def _step_response(gains: FilterGains, rate: float, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """Filter started at 0, then fed a constant 1.0: the error 1 - x_hat at each sample."""
    f = PoseFilter(gains)
    f.step(0.0, Measurement(0.0, 0.0, 0.0))
    times, errors = [], []
    for k in range(1, int(duration * rate) + 1):
        t = k / rate
        est = f.step(t, Measurement(1.0, 0.0, 0.0))
        times.append(t)
        errors.append(1.0 - est.x)
    return np.array(times), np.array(errors)


def _fitted_rate(times: np.ndarray, errors: np.ndarray, t_from: float) -> float:
    keep = (times >= t_from) & (np.abs(errors) > 1e-12)
    assert keep.sum() >= 3, "too few samples to fit"
    slope, _ = np.polyfit(times[keep], np.log(np.abs(errors[keep])), 1)
    return -slope


@pytest.mark.parametrize("rate,gains", [
    (1000.0, FilterGains(1000.0, 120.0)),     # the paper's gains and rate
    (40.0, FilterGains(1000.0, 120.0)),       # the same gains at a stock autopilot's 40 Hz
    (40.0, FilterGains(200.0, 10.0)),         # a slower filter at 40 Hz
    (1000.0, FilterGains(400.0, 5.0)),
])
def test_filter_error_decays_at_lambda_f(rate, gains):
    times, errors = _step_response(gains, rate, duration=max(8.0 / gains.lambda_f, 8.0 / rate))
    # After d_f (rate k_df) has died: five of its time constants.
    rate_fit = _fitted_rate(times, errors, t_from=5.0 / gains.k_df + 1.0 / rate)
    assert rate_fit == pytest.approx(gains.lambda_f, rel=0.01)


def test_filter_is_stable_where_forward_euler_is_not():
    # k_df * dt = 25 at 40 Hz: forward Euler of (7) would diverge; the exact step converges.
    times, errors = _step_response(FilterGains(1000.0, 120.0), 40.0, 1.0)
    assert np.all(np.isfinite(errors)) and abs(errors[-1]) < 1e-12


def test_transition_is_the_matrix_exponential():
    gains, dt = FilterGains(30.0, 7.0), 0.05
    a = np.array([[-gains.l1, 1.0], [-gains.l2, 0.0]])
    # exp by scaling and squaring of a Taylor series: independent of Sylvester's formula.
    m = a * dt / 1024
    e = np.eye(2)
    term = np.eye(2)
    for k in range(1, 20):
        term = term @ m / k
        e = e + term
    for _ in range(10):
        e = e @ e
    assert np.allclose(np.array(transition(gains, dt)).reshape(2, 2), e, rtol=1e-9, atol=1e-12)


def test_equal_roots_do_not_break_the_closed_form():
    p = transition(FilterGains(50.0, 50.0), 0.01)
    q = transition(FilterGains(50.0, 50.0 * (1 + 1e-4)), 0.01)
    assert np.allclose(p, q, rtol=1e-3)


def test_variable_dt_equals_the_same_interval_in_one_step():
    # Exact discretisation: two steps of 10 and 30 ms on the same held sample equal one of 40 ms.
    a, b = PoseFilter(FilterGains(300.0, 40.0)), PoseFilter(FilterGains(300.0, 40.0))
    for f in (a, b):
        f.step(0.0, Measurement(0.0, 0.0, 0.0))
        f.step(0.025, Measurement(0.3, -0.2, 0.1))
    a.step(0.035, Measurement(1.0, 2.0, 0.5))
    ea = a.step(0.065, Measurement(1.0, 2.0, 0.5))
    eb = b.step(0.065, Measurement(1.0, 2.0, 0.5))
    for key in ("x", "y", "yaw", "vx", "vy", "yaw_rate"):
        assert getattr(ea, key) == pytest.approx(getattr(eb, key), rel=1e-9, abs=1e-12)


def test_irregular_sample_times_track_a_moving_signal():
    rng = np.random.default_rng(3)
    f = PoseFilter(FilterGains(200.0, 30.0))
    t = 0.0
    for _ in range(400):
        t += rng.uniform(0.01, 0.06)          # 16-100 Hz with jitter
        est = f.step(t, Measurement(math.sin(t), 2.0 * t, 0.0))
    assert est.x == pytest.approx(math.sin(t), abs=0.06)
    assert est.y == pytest.approx(2.0 * t, abs=0.08)


def test_rate_state_estimates_the_rate_when_sampled_fast():
    # The rate state (the paper's Delta p_hat_v) is only as good as the hold between samples:
    # at 1 kHz the held sample is nearly the signal and the rate comes out right.
    f = PoseFilter(FilterGains(200.0, 30.0))
    for k in range(3001):
        est = f.step(k * 0.001, Measurement(2.0 * k * 0.001, 0.0, 0.0))
    assert est.vx == pytest.approx(2.0, rel=0.01)


@pytest.mark.parametrize("dt", [0.0, -0.01, float("nan")])
def test_time_that_does_not_advance_is_refused(dt):
    f = PoseFilter()
    f.step(1.0, Measurement(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="time must increase"):
        f.step(1.0 + dt, Measurement(0.0, 0.0, 0.0))


def test_yaw_through_pi_moves_the_short_way():
    f = PoseFilter(FilterGains(200.0, 30.0))
    f.step(0.0, Measurement(0.0, 0.0, math.pi - 0.05))
    yaws = []
    for k in range(1, 200):
        # The rover turns left through +pi: the sample wraps to about -pi.
        yaw = wrap(math.pi - 0.05 + 0.1 * min(k, 20) / 20)
        yaws.append(f.step(k * 0.01, Measurement(0.0, 0.0, yaw)).yaw)
    steps = np.abs(np.diff(np.unwrap(yaws)))
    assert steps.max() < 0.02                       # no jump through zero
    assert all(-math.pi < y <= math.pi for y in yaws)
    assert wrap(yaws[-1] - (math.pi + 0.05)) == pytest.approx(0.0, abs=1e-6)


def test_many_turns_stay_bounded_and_exact():
    f = PoseFilter(FilterGains(200.0, 30.0))
    rate = 2.0   # rad/s, for 100 s: 32 turns
    for k in range(0, 100001):
        t = k * 0.001
        est = f.step(t, Measurement(0.0, 0.0, wrap(rate * t)))
    assert abs(f.yaw) <= math.pi + 1.0              # internal state shifted by whole turns
    assert est.yaw_rate == pytest.approx(rate, rel=0.01)
    assert wrap(est.yaw - rate * t) == pytest.approx(0.0, abs=0.01)


def test_batch_filter_equals_single_filters():
    gains = FilterGains(np.array([1000.0, 200.0, 50.0]), np.array([120.0, 30.0, 5.0]))
    batch = PoseFilter(gains, n=3)
    singles = [PoseFilter(FilterGains(float(k), float(l))) for k, l in zip(gains.k_df, gains.lambda_f, strict=True)]
    rng = np.random.default_rng(0)
    for k in range(200):
        t = 0.02 * k
        xs, ys, yaws = rng.normal(size=3), rng.normal(size=3), rng.uniform(-3.2, 3.2, size=3)
        eb = batch.step(t, Measurement(xs, ys, yaws))
        for i, f in enumerate(singles):
            es = f.step(t, Measurement(xs[i], ys[i], yaws[i]))
            assert (es.x, es.y, es.yaw) == pytest.approx((eb.x[i], eb.y[i], eb.yaw[i]), abs=1e-12)
