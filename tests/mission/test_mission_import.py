"""QGroundControl .plan / QGC WPL 110 import and the ArduPilot lat/lon conversion."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from companion import mission as missions
from companion.errors import UserError
from companion.mission import geo

CMAC = (-35.363261, 149.165230)    # ArduPilot SITL's default home


def ardupilot_ne(lat, lon, lat0, lon0):
    """AP_Common/Location.cpp get_distance_NE from the origin, in single precision as on a
    flight controller: int32 1e-7 degrees, mean latitude by C integer division."""
    f = np.float32
    la, lo, la0, lo0 = (int(round(v * 1e7)) for v in (lat, lon, lat0, lon0))
    dlon = lo - lo0
    if dlon > 1_800_000_000:
        dlon -= 3_600_000_000
    elif dlon < -1_800_000_000:
        dlon += 3_600_000_000
    mean = int((la + la0) / 2)            # truncates towards zero, as C does
    scale = np.cos(f(mean) * f(1.0e-7 * math.pi / 180.0))
    scale = min(max(scale, f(0.01)), f(1.0))
    lsf = f(0.011131884502145034)
    return float(f(la - la0) * lsf), float(f(dlon) * lsf * scale)


def destination(lat, lon, bearing_deg, distance):
    """Great-circle destination (spherical earth): an independent way to place a point."""
    r = 6371000.0
    p1, l1, b = math.radians(lat), math.radians(lon), math.radians(bearing_deg)
    d = distance / r
    p2 = math.asin(math.sin(p1) * math.cos(d) + math.cos(p1) * math.sin(d) * math.cos(b))
    l2 = l1 + math.atan2(math.sin(b) * math.sin(d) * math.cos(p1),
                         math.cos(d) - math.sin(p1) * math.sin(p2))
    return math.degrees(p2), (math.degrees(l2) + 540.0) % 360.0 - 180.0


@pytest.mark.parametrize("lat0,lon0", [CMAC, (0.0, 0.0), (47.397742, 8.545594),
                                        (64.1, -21.9), (-0.5, 179.9995)])
@pytest.mark.parametrize("bearing", [0.0, 37.0, 90.0, 200.0, 315.0])
def test_conversion_matches_ardupilot_within_1cm_at_1km(lat0, lon0, bearing):
    lat, lon = destination(lat0, lon0, bearing, 1000.0)
    mine = geo.ne_from_latlon(lat, lon, (lat0, lon0))
    theirs = ardupilot_ne(lat, lon, lat0, lon0)
    assert math.dist(mine, theirs) < 0.01
    assert math.hypot(*mine) == pytest.approx(1000.0, rel=5e-3)   # flat earth ~ sphere at 1 km


def test_conversion_constant_and_clamp():
    north, east = geo.ne_from_latlon(1e-7, 1e-7, (0.0, 0.0))
    assert north == pytest.approx(0.011131884502145034)
    assert east == pytest.approx(0.011131884502145034)
    # Near the pole cos(lat) is clamped to 0.01.
    _, east = geo.ne_from_latlon(89.99999, 1.0, (89.99999, 0.0))
    assert east == pytest.approx(1e7 * 0.011131884502145034 * 0.01)


def test_latlon_round_trip_within_1cm():
    for north, east in ((1000.0, 0.0), (-250.5, 730.25), (3.0, -999.0)):
        lat, lon = geo.latlon_from_ne(north, east, CMAC)
        assert math.dist(geo.ne_from_latlon(lat, lon, CMAC), (north, east)) < 0.01


def _plan_file(tmp_path, items, name="m.plan", home=CMAC, **mission):
    body = {"cruiseSpeed": 2.0, "items": items, "version": 2, "firmwareType": 3,
            "vehicleType": 10}
    if home is not None:
        body["plannedHomePosition"] = [home[0], home[1], 584.0]
    body.update(mission)
    path = tmp_path / name
    path.write_text(json.dumps({"fileType": "Plan", "version": 1, "groundStation": "QGC",
                                "mission": body, "geoFence": {}, "rallyPoints": {}}))
    return path


def _item(command=16, lat=0.0, lon=0.0, p1=0.0, p2=0.0, frame=3):
    return {"type": "SimpleItem", "command": command, "frame": frame, "autoContinue": True,
            "doJumpId": 1, "params": [p1, p2, 0, None, lat, lon, 10.0]}


@pytest.mark.parametrize("origin", [None, destination(*CMAC, 120.0, 300.0)])
def test_plan_waypoint_1km_away_lands_within_1cm_of_ardupilot(tmp_path, origin):
    lat, lon = destination(*CMAC, 53.0, 1000.0)
    path = _plan_file(tmp_path, [_item(lat=lat, lon=lon)])
    m = missions.load(path, origin=origin)
    ekf = origin or CMAC
    end = m.trajectory.sample(m.duration)
    assert math.dist((end.x, end.y), ardupilot_ne(lat, lon, *ekf)) < 0.01
    start = m.trajectory.sample(0.0)
    assert math.dist((start.x, start.y), ardupilot_ne(*CMAC, *ekf)) < 0.01   # starts at home
    assert m.frame == "local" and m.anchored(5.0, 5.0, 1.0) is m.trajectory


def test_plan_follows_waypoints_at_cruise_speed(tmp_path):
    pts = [destination(*CMAC, 0.0, 30.0), destination(*CMAC, 30.0, 40.0)]
    m = missions.load(_plan_file(tmp_path, [_item(lat=a, lon=b) for a, b in pts],
                                 cruiseSpeed=1.25))
    assert m.kind == "plan" and m.warnings == ()
    assert m.profile.peak_speed == pytest.approx(1.25)
    assert len(m.trajectory.points) == 3
    faster = missions.load(tmp_path / "m.plan", speed=2.5)
    assert faster.profile.peak_speed == pytest.approx(2.5)
    assert faster.duration < m.duration


def test_items_not_followed_are_reported_one_line_each(tmp_path):
    a, b = destination(*CMAC, 0.0, 30.0), destination(*CMAC, 90.0, 30.0)
    items = [_item(command=22),                          # takeoff
             _item(lat=a[0], lon=a[1], p1=5.0),          # waypoint with a hold time
             _item(command=178, p2=3.0, frame=2),        # speed change after the path started
             _item(lat=b[0], lon=b[1]),
             _item(command=20)]                          # return to launch
    path = _plan_file(tmp_path, items)
    proc = subprocess.run([sys.executable, "-m", "companion", "mission", "check", str(path)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    warnings = proc.stderr.strip().splitlines()
    assert len(warnings) == 4, proc.stderr
    for index, text in ((0, "NAV_TAKEOFF (22)"), (1, "hold time 5 s"),
                        (2, "DO_CHANGE_SPEED (178)"), (4, "NAV_RETURN_TO_LAUNCH (20)")):
        assert any(f"mission.items[{index}]" in w and text in w for w in warnings), text
    assert all(w.startswith("companion mission: warning: ") for w in warnings)
    assert f"{path}: ok: plan" in proc.stdout


def test_waypoints_file_home_row_and_speed_item(tmp_path):
    a, b = destination(*CMAC, 10.0, 25.0), destination(*CMAC, 100.0, 25.0)
    rows = ["QGC WPL 110",
            f"0\t1\t0\t16\t0\t0\t0\t0\t{CMAC[0]}\t{CMAC[1]}\t584\t1",
            "1\t0\t3\t178\t0\t1.2\t-1\t0\t0\t0\t0\t1",
            f"2\t0\t3\t16\t0\t0\t0\t0\t{a[0]:.7f}\t{a[1]:.7f}\t10\t1",
            f"3\t0\t3\t16\t0\t0\t0\t0\t{b[0]:.7f}\t{b[1]:.7f}\t10\t1"]
    path = tmp_path / "m.waypoints"
    path.write_text("\n".join(rows) + "\n")
    m = missions.load(path)
    assert m.warnings == ()
    assert m.profile.peak_speed == pytest.approx(1.2)
    end = m.trajectory.sample(m.duration)
    assert math.dist((end.x, end.y), ardupilot_ne(float(f"{b[0]:.7f}"), float(f"{b[1]:.7f}"),
                                                  *CMAC)) < 0.01


def test_file_without_home_needs_an_origin(tmp_path):
    a, b = destination(*CMAC, 10.0, 25.0), destination(*CMAC, 50.0, 25.0)
    path = _plan_file(tmp_path, [_item(lat=a[0], lon=a[1]), _item(lat=b[0], lon=b[1])], home=None)
    with pytest.raises(UserError, match="no home position"):
        missions.load(path)
    m = missions.load(path, origin=CMAC)
    start = m.trajectory.sample(0.0)
    assert math.dist((start.x, start.y), ardupilot_ne(*a, *CMAC)) < 0.01


def test_toml_can_wrap_a_plan_with_limits(tmp_path):
    a = destination(*CMAC, 0.0, 30.0)
    _plan_file(tmp_path, [_item(lat=a[0], lon=a[1])], cruiseSpeed=3.0)
    toml = tmp_path / "wrapped.toml"
    toml.write_text('[trajectory]\nkind = "plan"\nfile = "m.plan"\n[limits]\nmax_speed = 2.0\n')
    with pytest.raises(UserError, match=r"limits\.max_speed"):
        missions.load(toml)
    toml.write_text('[trajectory]\nkind = "plan"\nfile = "m.plan"\nspeed = 1.5\n'
                    '[limits]\nmax_speed = 2.0\n')
    m = missions.load(toml)
    assert m.frame == "local" and m.profile.peak_speed == pytest.approx(1.5)


def test_geodetic_toml_is_placed_relative_to_the_ekf_origin(tmp_path):
    text = ('frame = "geodetic"\norigin = [-35.363261, 149.16523]\nduration = 30\n'
            '[trajectory]\nkind = "line"\nstart = [0.0, 0.0]\nend = [20.0, 0.0]\nspeed = 1\n')
    own = missions.loads(text)
    assert own.frame == "local"
    assert own.trajectory.sample(0.0).x == pytest.approx(0.0)
    ekf = destination(*CMAC, 180.0, 100.0)          # EKF origin 100 m south of the mission's
    moved = missions.loads(text, origin=ekf)
    r = moved.trajectory.sample(0.0)
    assert math.dist((r.x, r.y), ardupilot_ne(*CMAC, *ekf)) < 0.01
    assert r.x == pytest.approx(100.0, abs=0.5)


def test_shipped_plan_and_waypoints_describe_the_same_path():
    a = missions.load("missions/example_rover.plan")
    b = missions.load("missions/example_rover.waypoints")
    flat = [v for point in a.trajectory.points for v in point]
    assert flat == pytest.approx([v for point in b.trajectory.points for v in point])
    assert a.duration == pytest.approx(b.duration)
