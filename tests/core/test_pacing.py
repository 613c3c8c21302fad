"""The reference's pace (companion.core.pacing): a slowed clock's feed-forward, the ramp from
rest, and where a stopped rover rejoins its path."""

from __future__ import annotations

import math

import pytest

from companion.core import pacing
from companion.core.signals import Reference
from companion.core.trajectory import Ellipse


def test_a_slowed_clock_scales_velocity_by_the_rate_and_acceleration_by_its_square():
    ref = Reference(1.0, 2.0, 3.0, -1.0, 0.5, 0.25)
    p = pacing.paced(ref, 0.5)
    assert (p.x, p.y, p.vx, p.vy, p.ax, p.ay) == (1.0, 2.0, 1.5, -0.5, 0.125, 0.0625)
    q = pacing.paced(ref, 0.5, rate_dot=2.0)       # a changing rate adds r' p_ref'
    assert (q.ax, q.ay) == (0.125 + 6.0, 0.0625 - 2.0)


def test_the_ramp_is_the_integral_of_its_rate():
    T = 2.0
    ts = [k * 0.001 for k in range(4001)]
    integral = 0.0
    for a, b in zip(ts[:-1], ts[1:], strict=True):
        integral += 0.5 * (pacing.ramp(a, T)[1] + pacing.ramp(b, T)[1]) * (b - a)
        assert pacing.ramp(b, T)[0] == pytest.approx(integral, abs=1e-6)
    assert pacing.ramp(1.0, T) == (0.25, 0.5, 0.5)
    assert pacing.ramp(3.0, T) == (2.0, 1.0, 0.0)
    assert pacing.ramp(1.5, 0.0) == (1.5, 1.0, 0.0)
    assert pacing.ramp_seconds(1.2, 1.0) == pytest.approx(1.2)
    assert pacing.ramp_seconds(1.2, 0.0) == 0.0 and pacing.ramp_seconds(0.0, 1.0) == 0.0


def test_a_stopped_rover_rejoins_where_it_stands_never_behind_the_held_time():
    e = Ellipse.paper(0.04)
    held = 5.0
    ahead = e.sample(6.3)                      # it braked 1.3 s of path past the held time
    t = pacing.rejoin_time(e, held, ahead.x + 0.01, ahead.y, horizon=3.0)
    assert t == pytest.approx(6.3, abs=0.03)
    behind = e.sample(4.0)                     # it stands before: the clock does not go back
    assert pacing.rejoin_time(e, held, behind.x, behind.y, horizon=3.0) == held
    here = e.sample(held)
    assert pacing.rejoin_time(e, held, here.x, here.y, horizon=3.0) == held
    assert pacing.rejoin_time(e, held, 1e3, 1e3, horizon=3.0) == held   # not on the path
    off = e.sample(6.3)                      # past the held point but 0.5 m off the path
    speed = math.hypot(off.vx, off.vy)
    x, y = off.x - 0.5 * off.vy / speed, off.y + 0.5 * off.vx / speed
    assert pacing.rejoin_time(e, held, x, y, horizon=3.0, near=0.3) == held
