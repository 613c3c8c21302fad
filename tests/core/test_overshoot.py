"""The overshoot cancellation (companion.core.overshoot): the speed it sends, passed through the
vehicle model's own overshoot (companion.sim.actuator.overshoot_step), comes out as the law asked."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.core import ops
from companion.core.limits import Limits
from companion.core.overshoot import OvershootCancel
from companion.core.signals import Command
from companion.sim.actuator import overshoot_step

DT = 0.025


def through_the_vehicle(asked: np.ndarray, share: float, tau: float, cancel: bool):
    """The speeds ``asked`` (one per DT), sent as they are or through the cancellation, then
    overshot as the model's speed loop overshoots: (what was sent, what the vehicle drove)."""
    stage = OvershootCancel(share if cancel else 0.0, tau)
    z = x_last = 0.0                               # the vehicle at rest
    sent, driven = [], []
    for k, u in enumerate(asked):
        c = stage.step(k * DT, Command(float(u), 0.0, 0.0, 0.0)).speed
        v, z = overshoot_step(ops.scalar, x_last, c, z, share, tau, DT)
        x_last = c
        sent.append(c)
        driven.append(v)
    return np.array(sent), np.array(driven)


@pytest.mark.parametrize("share, tau", [(0.55, 1.23), (0.25, 1.9), (1.0, 0.3)])
def test_the_vehicle_drives_what_the_law_asked(share, tau):
    t = np.arange(0.0, 30.0, DT)
    asked = 1.0 + 0.4 * np.sin(1.0 * t) + 0.5 * (t > 10.0)      # a swing and a step
    _, plain = through_the_vehicle(asked, share, tau, cancel=False)
    sent, driven = through_the_vehicle(asked, share, tau, cancel=True)
    # without it the vehicle swings more than asked and overshoots the step
    assert np.max(np.abs(plain - asked)) > 0.1 * share
    # with it, what it drives is what was asked, to the model's own discretisation (its slow
    # state stepped with the command at its mean: an error of order share x DT / tau at a step)
    assert np.max(np.abs(driven - asked)) < 0.5 * share * DT / tau
    # what is sent swings less: the vehicle's overshoot taken out beforehand
    swing = lambda a: np.ptp(a[t > 12.0])  # noqa: E731
    assert swing(sent) < swing(asked) < swing(plain)


def test_nothing_changes_without_an_overshoot_and_the_limits_hold():
    stage = OvershootCancel(0.0, 1.0)
    cmd = Command(1.3, 0.4, 1.0, 0.2)
    assert stage.step(0.0, cmd) is cmd
    # a car's turning radius: the turn rate within what the sent speed allows
    car = OvershootCancel(0.5, 1.0, Limits(max_speed=2.0, max_yaw_rate=2.0, min_turn_radius=2.0))
    out = car.step(0.0, Command(2.0, 1.0, 0.0, 0.0))     # from rest: 2 / 1.5 sent
    assert out.speed == pytest.approx(2.0 / 1.5)
    assert out.yaw_rate == pytest.approx(out.speed / 2.0)
    for k in range(1, 400):                              # held: it settles on the command
        out = car.step(k * DT, Command(2.0, 1.0, 0.0, 0.0))
    assert out.speed == pytest.approx(2.0, abs=1e-3) and out.yaw_rate == pytest.approx(1.0, abs=1e-3)
    assert math.isfinite(out.speed)


def test_lanes_match_one_vehicle_each():
    shares, taus = np.array([0.0, 0.3, 0.8]), np.array([1.0, 0.5, 2.0])
    batch = OvershootCancel(shares, taus, n=3)
    singles = [OvershootCancel(float(g), float(tau)) for g, tau in zip(shares, taus, strict=True)]
    for k in range(200):
        u = 1.0 + math.sin(0.05 * k)
        got = batch.step(k * DT, Command(np.full(3, u), np.zeros(3), np.zeros(3), np.zeros(3)))
        want = [s.step(k * DT, Command(u, 0.0, 0.0, 0.0)).speed for s in singles]
        assert got.speed == pytest.approx(want, rel=1e-12)
