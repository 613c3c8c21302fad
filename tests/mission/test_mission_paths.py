"""Trajectory kinds: analytic derivatives, continuity, corners, limits."""

from __future__ import annotations

import bisect
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion import mission as missions
from companion.core.trajectory import Ellipse
from companion.mission.paths import Circle, FigureEight, PathError, Placed
from companion.mission.polyline import Polyline
from companion.mission.spline import TimedWaypoints

H = 1e-5   # central-difference step, s


def _fd_errors(traj, times):
    """Largest |velocity - d position/dt| and |acceleration - d velocity/dt| over ``times``."""
    ev = ea = 0.0
    for t in times:
        a, b, c = traj.sample(t - H), traj.sample(t), traj.sample(t + H)
        ev = max(ev, abs((c.x - a.x) / (2 * H) - b.vx), abs((c.y - a.y) / (2 * H) - b.vy))
        ea = max(ea, abs((c.vx - a.vx) / (2 * H) - b.ax), abs((c.vy - a.vy) / (2 * H) - b.ay))
    return ev, ea


def _away_from(times, knots, gap=1e-3):
    """Drop times within ``gap`` of a knot (where the acceleration of a polyline may jump)."""
    return [t for t in times if all(abs(t - k) > gap for k in knots)]


KINDS = {
    "ellipse": Ellipse(f_r=0.12, ax=6.0, bx=-1.0, ay=2.0, by=3.0, cx=1.0, cy=-2.0),
    "circle_cw": Circle(center=(1.0, 2.0), radius=3.0, speed=1.2, clockwise=True,
                        start_bearing=0.7),
    "circle_ccw": Circle(center=(0.0, 5.0), radius=5.0, speed=2.0, clockwise=False),
    "figure8": FigureEight(center=(1.0, -1.0), length=16.0, width=8.0, period=40.0,
                           heading=math.radians(30)),
    "line": Polyline(((0.0, 0.0), (12.0, 5.0)), speed=1.5, accel=0.8),
    "polyline": Polyline(((0.0, 0.0), (10.0, 0.0), (10.0, 6.0), (2.0, 12.0)), speed=1.0,
                         corner_radius=1.5),
    "polyline_closed": Polyline(((0.0, 0.0), (10.0, 0.0), (10.0, 6.0), (0.0, 6.0)), speed=1.0,
                                corner_radius=2.0, closed=True, laps=2),
    "waypoints": TimedWaypoints(((0.0, 0.0, 0.0), (5.0, 4.0, 1.0), (12.0, 6.0, 8.0),
                                 (20.0, -1.0, 9.0))),
    "waypoints_closed": TimedWaypoints(((2.0, 0.0, 0.0), (10.0, 6.0, 2.0), (18.0, 4.0, 9.0),
                                        (30.0, 0.0, 0.0)), closed=True),
    "placed": Placed(Circle(center=(0.0, 5.0), radius=5.0, speed=1.5), 3.0, -4.0, 2.0),
}


@pytest.mark.parametrize("name", sorted(KINDS))
def test_velocity_and_acceleration_are_derivatives_of_position(name):
    traj = KINDS[name]
    times = [0.013 + 0.377 * k for k in range(160)]
    knots = []
    if isinstance(traj, Polyline):
        # Arc ends: the acceleration jumps by v^2/r there (documented), so skip those instants.
        knots = _polyline_knot_times(traj)
    ev, ea = _fd_errors(traj, _away_from(times, knots))
    assert ev < 1e-6, ev
    assert ea < 1e-5, ea


def _polyline_knot_times(traj: Polyline, step: float = 1e-3) -> list[float]:
    """Times at which the path passes from one piece (side or arc) to the next, to +-step/2."""
    def piece(t):
        s = traj._profile.at(t)[0]
        if traj.closed:
            s %= traj.length
        return bisect.bisect_right(traj._starts, s)

    times, end = [], traj.motion_end
    prev, t = piece(0.0), 0.0
    while t < end:
        now = piece(t + step)
        if now != prev:
            times.append(t + step / 2)
        prev, t = now, t + step
    return times


def test_samples_are_plain_floats():
    for name, traj in KINDS.items():
        ref = traj.sample(1.25)
        assert all(type(v) is float for v in (ref.x, ref.y, ref.vx, ref.vy, ref.ax, ref.ay)), name


def test_circle_is_round_at_its_speed():
    c = KINDS["circle_cw"]
    for t in (0.0, 1.3, 7.7):
        r = c.sample(t)
        assert math.hypot(r.x - 1.0, r.y - 2.0) == pytest.approx(3.0)
        assert math.hypot(r.vx, r.vy) == pytest.approx(1.2)
    # Clockwise seen from above (north towards east): heading increases.
    r = c.sample(0.0)
    assert r.vx * r.ay - r.vy * r.ax > 0
    r = KINDS["circle_ccw"].sample(0.0)
    assert r.vx * r.ay - r.vy * r.ax < 0


def test_figure_eight_crosses_its_centre_and_repeats():
    f = KINDS["figure8"]
    a, b = f.sample(0.0), f.sample(20.0)
    assert (a.x, a.y) == pytest.approx((1.0, -1.0))
    assert (b.x, b.y) == pytest.approx((1.0, -1.0), abs=1e-9)
    c = f.sample(40.0)
    assert (c.x, c.y, c.vx, c.vy) == pytest.approx((a.x, a.y, a.vx, a.vy), abs=1e-9)


def test_polyline_starts_and_ends_at_rest_on_its_points():
    p = KINDS["polyline"]
    start, end = p.sample(0.0), p.sample(p.motion_end)
    assert (start.x, start.y, start.vx, start.vy) == pytest.approx((0.0, 0.0, 0.0, 0.0))
    assert (end.x, end.y) == pytest.approx((2.0, 12.0), abs=1e-9)
    assert (end.vx, end.vy) == pytest.approx((0.0, 0.0), abs=1e-9)
    assert p.sample(p.motion_end + 100.0).x == pytest.approx(2.0)


def test_polyline_corners_are_arcs_with_continuous_velocity():
    p = KINDS["polyline"]
    knots = _polyline_knot_times(p)
    assert len(knots) >= 4                     # two corners: four arc ends
    for t in knots:
        a, b = p.sample(t - 1e-7), p.sample(t + 1e-7)
        assert math.hypot(a.vx - b.vx, a.vy - b.vy) < 1e-5
    # On the arcs the path turns at speed / radius, never faster.
    peak = 0.0
    for k in range(1, 4000):
        r = p.sample(k * p.motion_end / 4000)
        v2 = r.vx ** 2 + r.vy ** 2
        if v2 > 1e-4:
            peak = max(peak, abs(r.vx * r.ay - r.vy * r.ax) / v2)
    assert peak == pytest.approx(1.0 / 1.5, rel=1e-3)
    assert p.peaks() == pytest.approx((1.0, 1.0 / 1.5))


def test_closed_polyline_runs_its_laps_and_stops():
    p = KINDS["polyline_closed"]
    assert p.period == pytest.approx(p.length / 1.0)
    end = p.sample(p.motion_end)
    start = p.sample(0.0)
    assert (end.x, end.y) == pytest.approx((start.x, start.y), abs=1e-6)
    assert math.hypot(end.vx, end.vy) < 1e-9


def test_corner_radius_too_large_is_an_error_naming_the_side():
    with pytest.raises(PathError) as err:
        Polyline(((0.0, 0.0), (10.0, 0.0), (10.0, 2.0), (0.0, 2.0)), speed=1.0, corner_radius=3.0)
    assert err.value.key == "corner_radius"
    assert "points[1] to points[2]" in str(err.value)
    # Shrinking (imported plans) fits it instead.
    p = Polyline(((0.0, 0.0), (10.0, 0.0), (10.0, 2.0), (0.0, 2.0)), speed=1.0, corner_radius=3.0,
                 shrink_corners=True)
    assert max(p.corner_radii) <= 1.0 + 1e-12


def test_reversal_and_coincident_points_are_errors():
    with pytest.raises(PathError) as err:
        Polyline(((0.0, 0.0), (10.0, 0.0), (0.0, 0.0)), speed=1.0)
    assert err.value.key == "points[1]"
    with pytest.raises(PathError) as err:
        Polyline(((0.0, 0.0), (10.0, 0.0), (10.0, 0.0)), speed=1.0)
    assert err.value.key == "points[2]"


def test_short_path_at_high_speed_is_an_error():
    with pytest.raises(PathError, match="too short"):
        Polyline(((0.0, 0.0), (2.0, 0.0)), speed=3.0, accel=0.5)


def _jumps(traj, t, eps=1e-7):
    a, b = traj.sample(t - eps), traj.sample(t + eps)
    return (math.hypot(a.x - b.x, a.y - b.y), math.hypot(a.vx - b.vx, a.vy - b.vy),
            math.hypot(a.ax - b.ax, a.ay - b.ay))


def test_waypoints_pass_through_their_points_continuously():
    w = KINDS["waypoints"]
    for t, x, y in w.waypoints:
        r = w.sample(t)
        assert (r.x, r.y) == pytest.approx((x, y), abs=1e-9)
        dp, dv, da = _jumps(w, t)
        assert dp < 1e-6 and dv < 1e-5 and da < 1e-4, (t, dp, dv, da)
    for t in (0.0, 20.0):   # at rest with zero acceleration at both ends
        r = w.sample(t)
        assert (r.vx, r.vy, r.ax, r.ay) == pytest.approx((0, 0, 0, 0), abs=1e-9)


def test_closed_waypoints_are_periodic():
    w = KINDS["waypoints_closed"]
    assert w.period == pytest.approx(28.0)
    for t in (10.0, 30.0, 38.0, 58.0):   # knots and lap boundaries (the wrap-around)
        dp, dv, da = _jumps(w, t)
        assert dp < 1e-6 and dv < 1e-5 and da < 1e-4
    # Before its first time the reference waits at the first waypoint.
    r = w.sample(1.0)
    assert (r.x, r.y, r.vx, r.vy) == (0.0, 0.0, 0.0, 0.0)
    a, b = w.sample(5.0), w.sample(33.0)
    assert (a.x, a.y, a.vx, a.vy, a.ax, a.ay) == pytest.approx((b.x, b.y, b.vx, b.vy, b.ax, b.ay))


def test_non_increasing_times_are_an_error():
    with pytest.raises(PathError) as err:
        TimedWaypoints(((0.0, 0.0, 0.0), (5.0, 1.0, 1.0), (5.0, 2.0, 2.0)))
    assert err.value.key == "waypoints[2]"


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(0.5, 10.0), st.floats(-20.0, 20.0), st.floats(-20.0, 20.0)),
                min_size=2, max_size=8))
def test_random_waypoint_splines_are_c2(steps):
    t, rows = 0.0, []
    for dt, x, y in steps:
        rows.append((t, x, y))
        t += dt
    w = TimedWaypoints(tuple(rows))
    scale = 1.0 + max(abs(v) for row in rows for v in row[1:])
    for t, x, y in rows:
        r = w.sample(t)
        assert (r.x, r.y) == pytest.approx((x, y), abs=1e-7 * scale)
        dp, dv, da = _jumps(w, t)
        assert dp < 1e-5 * scale and dv < 1e-4 * scale and da < 1e-3 * scale
    # Away from the knots, where the jerk (not checked here) may jump.
    times = _away_from([0.013 + 0.37 * k for k in range(int(rows[-1][0] / 0.37))],
                       [row[0] for row in rows])
    ev, ea = _fd_errors(w, times)
    assert ev < 1e-5 * scale and ea < 1e-3 * scale


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-30.0, 30.0), st.floats(-30.0, 30.0)), min_size=2,
                max_size=6),
       st.floats(0.2, 3.0), st.floats(0.1, 5.0))
def test_random_polylines_are_built_or_refused_cleanly(points, speed, radius):
    try:
        p = Polyline(tuple(points), speed=speed, corner_radius=radius)
    except PathError as err:
        assert err.key in ("speed", "corner_radius") or err.key.startswith("points[")
        return
    end = p.motion_end
    assert (p.sample(end).x, p.sample(end).y) == pytest.approx(points[-1], abs=1e-6)
    for k in range(200):
        r = p.sample(k * end / 199)
        assert math.hypot(r.vx, r.vy) <= speed * (1 + 1e-9)


def test_placed_turns_and_moves_a_trajectory():
    inner = Circle(center=(0.0, 5.0), radius=5.0, speed=1.5, start_bearing=math.radians(270))
    r0 = inner.sample(0.0)
    assert (r0.vx, r0.vy) == pytest.approx((1.5, 0.0), abs=1e-12)   # leaves straight ahead (north)
    placed = Placed(inner, 10.0, 20.0, math.pi / 2)                 # rover facing east at (10, 20)
    r = placed.sample(0.0)
    assert (r.x, r.y) == pytest.approx((10.0, 20.0), abs=1e-9)
    assert (r.vx, r.vy) == pytest.approx((0.0, 1.5), abs=1e-12)


def test_anchored_follows_the_frame():
    m = missions.loads('frame = "start"\nduration = 10\n[trajectory]\nkind = "circle"\n'
                       'center = [0.0, 5.0]\nradius = 5\nspeed = 1\nstart_bearing_deg = 270\n')
    r = m.anchored(3.0, 4.0, math.pi).sample(0.0)
    assert (r.x, r.y, r.vx, r.vy) == pytest.approx((3.0, 4.0, -1.0, 0.0), abs=1e-9)
    local = missions.loads('frame = "local"\nduration = 10\n[trajectory]\nkind = "circle"\n'
                           'radius = 5\nspeed = 1\n')
    assert local.anchored(3.0, 4.0, 1.0) is local.trajectory


def test_paper_ellipse_starts_where_the_paper_starts():
    m = missions.paper_ellipse()
    r = m.anchored(0.0, 0.0, 0.0).sample(0.0)
    assert (r.x, r.y) == (6.0, 2.0)
    assert m.duration == 60.0 and m.frame == "start" and m.period == pytest.approx(1 / 0.12)
    shipped = missions.load("missions/paper_ellipse_012.toml")
    a, b = shipped.trajectory.sample(3.3), m.trajectory.sample(3.3)
    assert (a.x, a.y, a.vx, a.vy) == pytest.approx((b.x, b.y, b.vx, b.vy))
