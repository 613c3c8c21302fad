"""The compiled channel loop (companion.sim.lag_series) is the numpy step loop, to rounding.

identification's fit runs ``lag_series``; numba compiles its per-model loop where numba is
installed, and ``compiled=False`` runs lag_step on arrays, one grid step a call (the reference,
and what runs without numba). Channel against ``respond``: tests/ident/test_identify.py.
"""

from __future__ import annotations

import platform

import numpy as np
import pytest

from companion.sim import lag_series as ls


def case(rng: np.random.Generator, n: int, steps: int, per_step_top: bool):
    """A smooth command with steps and reversals, per-model delays, clamps and limits."""
    t = np.arange(steps + 40) * 0.02
    cmd = 1.5 * np.sin(0.7 * t) + np.where(np.sin(0.13 * t) > 0.5, 1.0, -0.6)
    cmd[rng.random(len(cmd)) < 0.02] = 0.0          # a stop now and then
    offset = rng.integers(0, 40, n)
    if per_step_top:     # a clamp that moves with the other channel (the coupling's)
        top = 1.0 + 0.8 * np.abs(np.sin(0.2 * t[:steps]))[:, None] * rng.uniform(0.2, 1, n)
    else:
        top = rng.uniform(0.8, 3.0, (1, n))
    accel = rng.uniform(0.2, 6.0, n)
    accel[::7] = np.inf                              # no rate limit
    params = dict(bandwidth=rng.uniform(0.5, 40.0, n), accel=accel,
                  decel=np.where(rng.random(n) < 0.5, accel, rng.uniform(0.2, 6.0, n)),
                  overshoot=np.where(rng.random(n) < 0.3, 0.0, rng.uniform(-0.4, 0.6, n)),
                  overshoot_s=rng.uniform(0.2, 3.0, n))
    return cmd, offset, top, params


@pytest.mark.parametrize("capped", [False, True])
@pytest.mark.parametrize("per_step_top", [False, True])
@pytest.mark.parametrize("dt", [0.01, 0.02])
def test_compiled_loop_is_the_numpy_step_loop(per_step_top, dt, capped):
    rng = np.random.default_rng(7)
    cmd, offset, top, params = case(rng, 64, 3000, per_step_top)
    fast = ls.lag_series(cmd, offset, top, 3000, 0.4, dt=dt, capped=capped, **params)
    ref = ls.lag_series(cmd, offset, top, 3000, 0.4, dt=dt, compiled=False, capped=capped,
                        **params)
    assert fast.shape == ref.shape == (3000, 64)
    assert np.all(np.isfinite(ref))
    assert np.ptp(ref) > 1.0                  # the channels moved: ramps, clamps and lags
    assert np.max(np.abs(fast - ref)) < 1e-12
    assert np.all(fast[0] == 0.4)


def test_scalar_parameters_and_no_overshoot_are_the_array_case():
    rng = np.random.default_rng(3)
    cmd, offset, top, _ = case(rng, 16, 1500, False)
    scalar = ls.lag_series(cmd, offset, top, 1500, 0.0, bandwidth=5.0, accel=1.0, decel=2.0,
                           dt=0.02, overshoot=0.0, overshoot_s=1.0)
    arrays = ls.lag_series(cmd, offset, top, 1500, 0.0, bandwidth=np.full(16, 5.0),
                           accel=np.full(16, 1.0), decel=np.full(16, 2.0), dt=0.02,
                           overshoot=np.zeros(16), overshoot_s=np.ones(16), compiled=False)
    assert np.max(np.abs(scalar - arrays)) < 1e-12
    # A rate limit of 1 m/s^2 at most 0.02 per step, whatever the lag asks.
    assert np.max(np.abs(np.diff(scalar, axis=0))) <= 1.0 * 0.02 * 2.0 + 1e-12


@pytest.mark.parametrize("capped", [False, True])
def test_the_loop_as_python_is_the_numpy_step_loop(capped):
    """The per-model arithmetic itself (what numba compiles), run as plain Python."""
    rng = np.random.default_rng(11)
    cmd, offset, top, p = case(rng, 6, 400, True)
    b, up, down, g, tau = ls._params(6, p["bandwidth"], p["accel"], p["decel"], p["overshoot"],
                                     p["overshoot_s"])
    out = np.empty((400, 6))
    ls._loop(cmd, offset.astype(np.int64), top, 0.2, b, up, down, g, tau, 0.02, True, capped,
             out)
    ref = ls.lag_series(cmd, offset, top, 400, 0.2, dt=0.02, compiled=False, capped=capped, **p)
    assert np.max(np.abs(out - ref)) < 1e-12


def test_a_capped_overshoot_stays_within_the_clamp_and_the_lag_runs_on():
    """The turn rate's channel (``capped``): a feed-forward that over-drives shows its
    overshoot up to the clamp and no further (the motors give no more), where an uncapped one
    goes past it; a channel without overshoot is the same either way."""
    cmd = np.concatenate([np.zeros(10), np.full(300, 2.0), np.zeros(300)])
    offset, top = np.zeros(3, dtype=np.int64), np.array([[2.2, 2.2, 2.2]])
    kw = dict(bandwidth=10.0, accel=np.inf, decel=np.inf, dt=0.02,
              overshoot=np.array([0.8, 0.8, 0.0]), overshoot_s=1.0)
    free = ls.lag_series(cmd, offset, top, 600, 0.0, **kw)
    capped = ls.lag_series(cmd, offset, top, 600, 0.0, capped=True, **kw)
    assert free[:, 0].max() > 3.0                     # 2 rad/s asked, 1.8 x 2 at its peak
    assert capped[:, 0].max() == pytest.approx(2.2)   # the cap, held a while
    assert np.sum(capped[:, 0] == 2.2) > 10
    # the lag and the slow state ran on uncapped: once the overshoot is back below the cap
    # the two agree, and both settle on the command
    assert np.array_equal(capped[250:, 0], free[250:, 0])
    assert capped[305, 0] == pytest.approx(2.0, abs=0.01)
    assert np.array_equal(capped[:, 2], free[:, 2])   # no overshoot: nothing capped


@pytest.mark.skipif(platform.machine().lower() not in {"x86_64", "amd64", "aarch64", "arm64"},
                    reason="numba has no wheels here: the numpy loop runs")
def test_numba_compiles_the_loop_where_it_has_wheels():
    """pyproject installs numba on these machines; without it a fit is about 4x slower."""
    assert ls._compiled is not None
