"""The delay prediction (companion.core.predict): the pose the speed commands in flight lead to,
pinned against a rover that really applies its speed commands d seconds late."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from companion.core.filter import FilterGains
from companion.core.limits import Limits
from companion.core.predict import DelayPrediction
from companion.core.pzc import PZCGains, PZCTracker
from companion.core.signals import Command, Estimate, Reference
from companion.core.trajectory import Ellipse
from companion.sim.batch import SimConfig, simulate
from companion.sim.plant import RoverParams

DT = 0.025


def delayed_drive(delay: float, speeds, yaw_rate: float, horizon: float):
    """A unicycle that applies each speed command ``delay`` s after it was sent (the turn rate
    at once); at each step the prediction's pose against where the rover is ``horizon`` later."""
    pred = DelayPrediction(horizon)
    n = len(speeds)
    steps = int(round(delay / DT))
    x = y = yaw = 0.0
    poses, predicted = [], []
    for k in range(n):
        poses.append((x, y))
        est = Estimate(x, y, yaw, 0.0, 0.0, 0.0)
        ahead, _ = pred.step(k * DT, est, Reference(0.0, 0.0))
        predicted.append((ahead.x, ahead.y))
        pred.sent(k * DT, Command(speeds[k], yaw_rate, 0.0, 0.0))
        v = speeds[k - steps] if k >= steps else 0.0     # what lands now was sent delay ago
        # exact arc over the step with v and yaw_rate held
        if abs(yaw_rate) > 1e-12:
            x += v / yaw_rate * (math.sin(yaw + yaw_rate * DT) - math.sin(yaw))
            y -= v / yaw_rate * (math.cos(yaw + yaw_rate * DT) - math.cos(yaw))
        else:
            x += v * DT * math.cos(yaw)
            y += v * DT * math.sin(yaw)
        yaw += yaw_rate * DT
    lead = int(round(horizon / DT))
    return np.array(poses[lead:]), np.array(predicted[:n - lead])


def test_a_straight_run_is_predicted_exactly_where_the_delay_is_the_horizon():
    rng = np.random.default_rng(1)
    speeds = np.clip(np.cumsum(rng.normal(0.0, 0.05, 400)) + 1.0, 0.0, 3.0)
    actual, predicted = delayed_drive(0.5, speeds, 0.0, 0.5)
    assert np.max(np.abs(actual - predicted)) < 1e-9


def test_a_turn_is_predicted_to_a_millimetre():
    speeds = np.full(400, 2.0)
    speeds[200:] = 1.0                                # a step of the speed command mid-turn
    actual, predicted = delayed_drive(0.5, speeds, 0.5, 0.5)
    assert np.max(np.hypot(*(actual - predicted).T)) < 1e-3


def test_the_reference_is_taken_the_horizon_ahead():
    pred = DelayPrediction(0.4)
    pred.step(0.0, Estimate(0, 0, 0, 0, 0, 0), Reference(0, 0))
    # a reference with constant acceleration: p(t) = p0 + v t + a t^2 / 2, exact
    _, ahead = pred.step(DT, Estimate(0, 0, 0, 0, 0, 0), Reference(1.0, 2.0, 0.5, -1.0, 0.2, 0.4))
    assert (ahead.x, ahead.y) == pytest.approx((1.0 + 0.2 + 0.016, 2.0 - 0.4 + 0.032))
    assert (ahead.vx, ahead.vy) == pytest.approx((0.58, -0.84))


def test_off_by_default_and_the_same_on_arrays_as_on_floats():
    est, ref = Estimate(1.0, 2.0, 0.3, 0, 0, 0), Reference(3.0, 4.0, 1.0, 0.0)
    off = DelayPrediction(PZCGains().predict_s)
    assert off.step(0.0, est, ref) == (est, ref)
    horizons = [0.5, 0.0, 0.2]
    batch = DelayPrediction(np.array(horizons), n=3)
    singles = [DelayPrediction(h) for h in horizons]
    lane = np.arange(3)
    for k in range(120):
        t, yaw = k * DT, 0.01 * k
        speed, rate = 1.0 + math.sin(0.2 * k), 0.3 * math.cos(0.1 * k)
        # each lane its own heading, speed and turn rate (the lanes' arithmetic is one array)
        yaws, speeds, rates = yaw + 0.2 * lane, speed * (1 + 0.1 * lane), rate * (1 - 0.3 * lane)
        zero = np.zeros(3)
        many, _ = batch.step(t, Estimate(np.full(3, 0.1 * k), np.full(3, -0.05 * k), yaws, zero,
                                         zero, zero), ref)
        batch.sent(t, Command(speeds, rates, 0.0, 0.0))
        for i, single in enumerate(singles):
            one, _ = single.step(t, Estimate(0.1 * k, -0.05 * k, float(yaws[i]), 0, 0, 0), ref)
            single.sent(t, Command(float(speeds[i]), float(rates[i]), 0.0, 0.0))
            assert (many.x[i], many.y[i]) == pytest.approx((one.x, one.y), abs=1e-12)
    assert len(batch._sent) <= int(0.5 / DT) + 2         # it forgets what has landed


def test_a_rover_whose_speed_lands_half_a_second_late_tracks_four_times_closer():
    """The paper's ellipse at 0.08 Hz on a unicycle whose speed commands land 0.5 s late (the
    turn rate at once), the same PZC gains with and without the prediction: without it, 0.25 m;
    with it, 0.06 m (the same rover without the delay: 0.02 m)."""
    gains = PZCGains(1.0, 0.5, k_dc_yaw=5.0, lambda_c_yaw=3.0, velocity_ff=True,
                     heading_rate_ff=True)
    late = RoverParams(w_c=20.0, speed_delay=0.5)
    sim = SimConfig(duration=60.0, control_rate=40.0, max_plant_dt=0.005, noise_pos=0.0,
                    noise_yaw=0.0, seed=1)

    def fly(g: PZCGains, rover: RoverParams) -> float:
        tracker = PZCTracker(FilterGains(300.0, 40.0), g, Limits(6.0, 3.0))
        return float(simulate(tracker, rover, Ellipse.paper(0.08), None, sim).steady_rms)

    without = fly(gains, late)
    with_it = fly(replace(gains, predict_s=0.5), late)
    assert without > 0.2
    assert with_it < 0.1 and with_it < 0.3 * without, (with_it, without)
