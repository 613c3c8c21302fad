"""The seeded GNSS error model the injector feeds ArduPilot SITL (testbed.gnss, issue 44):
its statistics are the sizes it claims, its windows where they say, its seeds repeatable."""

from __future__ import annotations

import math

import numpy as np
import pytest

from testbed.gnss import (
    FIX_3D,
    FIX_RTK_FIXED,
    FIX_RTK_FLOAT,
    SCENARIOS,
    Drift,
    fixes,
    gauss_markov,
)


def test_gauss_markov_has_its_sigma_and_its_correlation_time():
    rng = np.random.default_rng(3)
    dt, drift = 0.1, Drift(0.5, 8.0)
    x = gauss_markov(400_000, dt, drift, rng)
    assert abs(x.std() - 0.5) < 0.02
    lag = int(round(drift.tau / dt))            # one tau later the correlation is 1/e
    r = np.corrcoef(x[:-lag], x[lag:])[0, 1]
    assert abs(r - math.exp(-1.0)) < 0.03, r
    grown = gauss_markov(11, 1.0, Drift(0.4, 1e6), rng, from_zero=True)
    assert grown[0] == 0.0 and np.abs(grown).max() < 0.4 * 0.1   # far slower than its tau


def test_no_error_is_no_error_at_ten_hertz():
    f = fixes(SCENARIOS["none"], 60.0, seed=1)
    assert len(f.t) == 601 and f.t[1] == 0.1
    assert not f.north.any() and not f.east.any()
    assert (f.fix_type == FIX_RTK_FIXED).all()


def test_rtk_float_is_fix_type_5_for_its_fifteen_seconds_and_decimetres():
    f = fixes(SCENARIOS["rtk-float"], 60.0, seed=1)
    inside = (f.t >= 20.0) & (f.t < 35.0)
    assert (f.fix_type[inside] == FIX_RTK_FLOAT).all()
    assert (f.fix_type[~inside] == FIX_RTK_FIXED).all()
    assert (f.h_acc[inside] == 0.4).all() and (f.h_acc[~inside] < 0.02).all()
    outside_err = np.hypot(f.north[~inside], f.east[~inside])
    assert outside_err.max() < 0.1                     # centimetres while fixed
    assert np.hypot(f.north[inside], f.east[inside]).max() > 0.1   # decimetres in float


def test_multipath_jumps_a_quarter_metre_while_still_fixed():
    s = SCENARIOS["multipath"]
    f = fixes(s, 60.0, seed=2)
    base = fixes(type(s)(s.name, white=s.white, drift=s.drift), 60.0, seed=2)
    assert (f.fix_type == FIX_RTK_FIXED).all()
    for start in (15.0, 30.0, 45.0):
        inside = (f.t >= start) & (f.t < start + 4.0)
        jump = np.hypot(f.north[inside] - base.north[inside], f.east[inside] - base.east[inside])
        assert np.allclose(jump, 0.25)


def test_plain_gps_is_a_3d_fix_at_five_hertz_wandering_half_a_metre():
    s = SCENARIOS["plain-gps"]
    assert (s.rate_hz, s.lag, s.fix_type) == (5.0, 0.2, FIX_3D)
    errs = [np.concatenate([fixes(s, 600.0, seed).north for seed in range(20)])]
    assert 0.35 < np.std(errs) < 0.65      # 0.5 m drift and 0.1 m white: sqrt(0.26) = 0.51


def test_a_seed_repeats_and_another_differs():
    a, b = fixes(SCENARIOS["rtk-fixed"], 30.0, 7), fixes(SCENARIOS["rtk-fixed"], 30.0, 7)
    c = fixes(SCENARIOS["rtk-fixed"], 30.0, 8)
    assert np.array_equal(a.north, b.north) and not np.array_equal(a.north, c.north)


def test_the_truth_on_the_vehicle_clock_is_free_of_each_links_delivery():
    """A rover on a 5 m circle at 1 m/s; the truth's link delivers 5 ms after the vehicle's
    clock, the companion's 35 ms, with jitter: matched by wall time the two disagree by the
    30 ms (3 cm at 1 m/s, turning with the heading, so the anchoring cannot take it out), on
    the vehicle's clock by nothing."""
    from testbed.gnss import SCENARIOS
    from testbed.gnss_flight import Truth, score

    rng = np.random.default_rng(2)
    vehicle = np.arange(0.0, 60.0, 0.025)                 # s, the vehicle's clock
    north, east = 5.0 * np.cos(vehicle / 5.0), 5.0 * np.sin(vehicle / 5.0)
    boot_wall = 1000.0
    truth_walls = boot_wall + vehicle + 0.005 + rng.uniform(0, 0.004, len(vehicle))
    samples = list(zip(truth_walls.tolist(), north.tolist(), east.tolist(), strict=True))
    clock = [(w + rng.uniform(0, 0.001), float(t))
             for w, t in zip(truth_walls, vehicle, strict=True)]
    # the companion's samples: the estimate exact (the truth's frame), the reference on it
    trace = [(boot_wall + t + 0.035 + rng.uniform(0, 0.004), t, n, e, n, e, t)
             for t, n, e in zip(vehicle[100:-100], north[100:-100], east[100:-100],
                                strict=True)]
    on_clock = score(trace, Truth(samples, clock), SCENARIOS["none"], 55.0, boot_wall)
    by_wall = score([r[:6] for r in trace], Truth(samples), SCENARIOS["none"], 55.0, boot_wall)
    assert on_clock["matched"] == "vehicle time" and by_wall["matched"] == "wall time"
    assert on_clock["floor"] < 0.002
    assert 0.025 < by_wall["floor"] < 0.065


def test_a_window_without_tracked_cycles_is_still_scored_from_the_truth():
    """A rover held through the whole fault window has no tracked cycles in it; its distance
    from the path is its true place all the same (here 0.2 m off the path, standing)."""
    from testbed.gnss import SCENARIOS
    from testbed.gnss_flight import score

    float_ = SCENARIOS["rtk-float"]
    w = float_.windows[0]
    t0 = 1000.0
    vehicle = np.arange(0.0, 60.0, 0.025)
    held = (vehicle >= w.start) & (vehicle < w.start + w.duration + 2.0)
    east = np.where(held, w.start, vehicle)                  # stands while held
    north = np.where(held, 0.2, 0.0)                         # 0.2 m off the path
    samples = list(zip((t0 + vehicle).tolist(), north.tolist(), east.tolist(), strict=True))
    trace = [(t0 + t, t, 0.0, t, 0.0, t) for t in vehicle[~held]]      # tracked cycles only
    from testbed.gnss_flight import Truth
    fault = score(trace, Truth(samples), float_, 55.0, t0)["faults"][0]
    assert math.isnan(fault["worst"])                         # nothing tracked inside
    assert fault["from_path"] == pytest.approx(0.2, abs=1e-6)
