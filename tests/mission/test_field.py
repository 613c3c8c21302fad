"""companion.mission.field and the ``kind = "field"`` mission: swaths at the spacing across the
area inside the headland, turns that stay in the headland, the entry corner, and one-line
errors."""

from __future__ import annotations

import math

import pytest
from shapely.geometry import LineString, Polygon

from companion import mission as missions
from companion.errors import UserError
from companion.mission.field import plan
from companion.mission.paths import PathError
from companion.mission.route import RouteLimits
from testbed.process import companion_cli

FIELD = [(0.0, 0.0), (20.0, 0.0), (20.0, 12.0), (0.0, 12.0)]   # 20 m north, 12 m east
LIM = RouteLimits(speed=1.0)


def test_a_rectangle_gets_swaths_at_the_spacing_inside_the_headland():
    fp = plan(FIELD, spacing=1.0, headland=3.0, angle=0.0, limits=LIM)
    assert len(fp.swaths) == 6
    easts = [a[1] for a, _ in fp.swaths]
    assert easts == pytest.approx([3.5, 4.5, 5.5, 6.5, 7.5, 8.5])   # 0.5 m inside the edges
    for k, (a, b) in enumerate(fp.swaths):
        assert sorted([a[0], b[0]]) == pytest.approx([3.0, 17.0])
        assert (b[0] > a[0]) == (k % 2 == 0)                        # alternating
    assert fp.covered == pytest.approx(1.0)
    assert fp.turn_radius == 0.5
    # the route never leaves the field, and covers each swath on a straight
    route = LineString(fp.route.outline())
    assert Polygon(FIELD).buffer(1e-6).contains(route)
    straights = [LineString(s) for s in fp.route.straights()]
    for a, b in fp.swaths:
        assert any(st.buffer(1e-6).contains(LineString([a, b])) for st in straights)


def test_without_an_angle_the_swaths_run_along_the_long_side():
    fp = plan(FIELD, spacing=1.0, headland=1.0, limits=LIM)
    assert math.degrees(fp.angle) % 180 == pytest.approx(0.0, abs=1e-6)
    turned = [(e, n) for n, e in FIELD]          # 12 m north, 20 m east
    fp = plan(turned, spacing=1.0, headland=1.0, limits=LIM)
    assert math.degrees(fp.angle) % 180 == pytest.approx(90.0, abs=1e-6)
    assert len(fp.swaths) == 10


def test_the_entry_is_the_corner_nearest_the_start():
    for start in [(3.0, 3.0), (17.0, 3.0), (3.0, 9.0), (17.0, 9.0)]:
        fp = plan(FIELD, spacing=1.0, headland=3.0, angle=0.0, limits=LIM, start=start)
        first = fp.route.sample(0.0)
        assert math.dist((first.x, first.y), start) < 1.0


@pytest.mark.parametrize("kwargs,key", [
    (dict(spacing=0.0, headland=1.0), "spacing"),
    (dict(spacing=1.0, headland=7.0), "headland"),     # leaves nothing 12 m across
    (dict(spacing=1.0, headland=0.0), "headland"),     # no room to turn
])
def test_impossible_fields_name_the_key(kwargs, key):
    with pytest.raises(PathError) as err:
        plan(FIELD, limits=LIM, **kwargs)
    assert err.value.key == key


def test_a_concave_field_is_refused_not_crossed():
    u_shape = [(0, 0), (20, 0), (20, 12), (0, 12), (0, 8), (14, 8), (14, 4), (0, 4)]
    with pytest.raises(PathError, match="concave"):
        plan(u_shape, spacing=1.0, headland=1.0, angle=math.pi / 2, limits=LIM)


def test_a_field_mission_file_checks_and_says_what_it_planned(tmp_path):
    path = tmp_path / "f.toml"
    path.write_text('frame = "local"\n[trajectory]\nkind = "field"\n'
                    f"boundary = {[list(p) for p in FIELD]}\n"
                    "spacing = 1.0\nheadland = 3.0\nangle_deg = 0\nspeed = 1.0\n")
    m = missions.load(path)
    assert m.kind == "field" and m.duration == pytest.approx(m.trajectory.motion_end)
    assert "6 swaths at 1 m" in m.summary()
    proc = companion_cli("mission", "check", str(path), timeout=60)
    assert proc.returncode == 0 and "6 swaths" in proc.stdout, proc.stderr


@pytest.mark.parametrize("body,text", [
    ("spacing = -1.0\nheadland = 3.0\nspeed = 1.0\n", "spacing"),
    ("spacing = 1.0\nspeed = 1.0\n", "headland"),
    ("spacing = 1.0\nheadland = 9.0\nspeed = 1.0\n", "headland"),
    ("spacing = 1.0\nheadland = 3.0\nspeed = 1.0\nturn_rate = 0\n", "turn_rate"),
])
def test_bad_field_keys_are_one_line_errors(tmp_path, body, text):
    path = tmp_path / "f.toml"
    path.write_text('[trajectory]\nkind = "field"\n'
                    f"boundary = {[list(p) for p in FIELD]}\n" + body)
    with pytest.raises(UserError) as err:
        missions.load(path)
    line = str(err.value)
    assert "\n" not in line and str(path) in line and text in line


def test_the_cover_moves_with_a_mission_placed_around_another_origin(tmp_path):
    path = tmp_path / "g.toml"
    path.write_text('frame = "geodetic"\norigin = [-35.363261, 149.165230]\n[trajectory]\n'
                    'kind = "field"\n'
                    f"boundary = {[list(p) for p in FIELD]}\n"
                    "spacing = 1.0\nheadland = 3.0\nangle_deg = 0\nspeed = 1.0\n")
    m = missions.load(path, origin=(-35.3633, 149.1652))      # the EKF origin elsewhere
    cover = m.field_cover()
    assert cover is not None
    first = m.trajectory.sample(m.duration * 0.05)              # on the first swath
    (a, b) = cover.swaths[0]
    side = ((b[0] - a[0]) * (first.y - a[1]) - (b[1] - a[1]) * (first.x - a[0])) / math.dist(a, b)
    assert abs(side) < 1e-6 and math.dist(a, (3.0, 3.5)) > 1.0   # moved, and on the route
