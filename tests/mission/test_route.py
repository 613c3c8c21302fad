"""companion.mission.route: the speed law along straights and arcs keeps to every limit, is
continuous, starts and ends at rest, and drives each piece as fast as its limit allows."""

from __future__ import annotations

import math

import pytest

from companion.mission.paths import PathError
from companion.mission.route import Route, RouteLimits, speed_law


def _walk(route: Route, dt: float = 0.002):
    t, end = 0.0, route.motion_end + 0.5
    while t <= end:
        yield t, route.along(t), route.sample(t)
        t += dt


def test_a_straight_ramps_up_and_down_along_half_cosines():
    lim = RouteLimits(speed=2.0, accel=0.5)
    route = Route(((0.0, 0.0), (20.0, 0.0)), lim)
    ramp = math.pi * 2.0 / (2 * 0.5)              # T = pi V / (2 A): 6.28 s, V T / 2 = 6.28 m
    cruise = (20.0 - 2.0 * ramp) / 2.0            # the rest at 2 m/s
    assert route.motion_end == pytest.approx(2 * ramp + cruise)
    s, v, a = route.along(ramp / 2)               # half way up: half the speed, peak accel
    assert (v, a) == pytest.approx((1.0, 0.5))
    assert s == pytest.approx(ramp / 2 - ramp / math.pi)
    assert route.along(ramp)[1:] == pytest.approx((2.0, 0.0))   # no step in the acceleration
    assert route.along(100.0) == (20.0, 0.0, 0.0)
    r = route.sample(ramp + cruise / 2)
    assert (r.x, r.y, r.vx, r.vy) == pytest.approx((10.0, 0.0, 2.0, 0.0))


def test_a_short_piece_is_a_triangle():
    mean = 2 * 0.5 / math.pi                      # a raised cosine's mean acceleration
    phases, peaks = speed_law([1.0], [5.0], accel=0.5)
    assert peaks == [pytest.approx(math.sqrt(mean))]          # sqrt(a L)
    assert phases[-1].t0 == pytest.approx(2 * math.sqrt(mean) / mean)


@pytest.mark.parametrize("turn_rate,lateral", [(0.5, 0.5), (2.0, 0.3), (0.2, 5.0)])
def test_the_law_keeps_every_limit_and_is_continuous(turn_rate, lateral):
    lim = RouteLimits(speed=1.5, turn_rate=turn_rate, lateral_accel=lateral, accel=0.4)
    # a zig-zag with right-angle and sharp corners
    route = Route(((0, 0), (10, 0), (10, 1), (0, 1), (0, 2), (6, 8)), lim, corner_radius=0.5)
    prev = prev_ref = None
    pa = 0.0
    for t, (s, v, a), ref in _walk(route):
        assert -1e-9 <= v <= lim.speed + 1e-9
        assert abs(a) <= lim.accel + 1e-9
        speed = math.hypot(ref.vx, ref.vy)
        assert speed == pytest.approx(v, abs=1e-9)
        if speed > 0.05:
            rate = abs(ref.vx * ref.ay - ref.vy * ref.ax) / speed ** 2
            assert rate <= lim.turn_rate * (1 + 1e-6)
            assert rate * speed <= lim.lateral_accel * (1 + 1e-6)
        if prev is not None and prev_ref is not None:
            ps, pv, pt = prev
            assert s >= ps - 1e-12                          # never backwards
            assert abs(v - pv) <= lim.accel * (t - pt) + 1e-9   # no jump in speed
            # nor in the acceleration (a short change of speed is a quick half cosine: small)
            assert abs(a - pa) <= lim.accel * math.pi * (t - pt) + 0.05 * lim.accel
            assert math.hypot(ref.x - prev_ref.x, ref.y - prev_ref.y) <= v * (t - pt) + 0.01
        prev, prev_ref, pa = (s, v, t), ref, a
    assert route.along(route.motion_end) == pytest.approx((route.length, 0.0, 0.0), abs=1e-6)
    peak_speed, peak_rate = route.peaks()
    assert peak_rate <= lim.turn_rate * (1 + 1e-9) and peak_speed <= lim.speed


def test_straights_go_at_the_straight_speed_and_turns_at_the_turns():
    lim = RouteLimits(speed=1.0, turn_rate=0.5, accel=0.5)
    route = Route(((0, 0), (20, 0), (20, 1), (0, 1)), lim, corner_radius=0.5)
    speeds = [v for _, (_, v, _), _ in _walk(route, 0.01)]
    assert max(speeds) == pytest.approx(1.0)
    assert route.peaks() == pytest.approx((1.0, 0.5))
    # in the turn (radius 0.5 m) the speed is turn_rate x r = 0.25 m/s
    t_turn = next(t for t, (s, _, _), _ in _walk(route, 0.01) if s > 19.6 + 0.3)
    assert route.along(t_turn)[1] == pytest.approx(0.25)
    assert route.turn_count() == 2 and len(route.straights()) == 2   # the 1 m side is all turn


def test_bad_limits_name_the_key():
    with pytest.raises(PathError) as err:
        Route(((0, 0), (1, 0)), RouteLimits(speed=1.0, turn_rate=0.0))
    assert err.value.key == "turn_rate"
