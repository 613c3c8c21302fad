"""Bad mission files fail before anything moves: exit code 2, one line naming file, key and value.

Every malformed file below is checked by a real ``python -m companion mission check`` process
(started all at once, so the set stays quick on two cores).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from testbed.process import companion_cli

CIRCLE = '[trajectory]\nkind = "circle"\nradius = 5.0\nspeed = 1.0\n'
HOME = [-35.363261, 149.16523, 584]


def _plan(items, **mission):
    body = {"cruiseSpeed": 1.5, "plannedHomePosition": HOME, "items": items, "version": 2}
    body.update(mission)
    return json.dumps({"fileType": "Plan", "version": 1, "mission": body})


def _wp(lat=-35.3630364, lon=149.16523, command=16, frame=3, params=None):
    return {"type": "SimpleItem", "command": command, "frame": frame, "autoContinue": True,
            "params": params or [0, 0, 0, None, lat, lon, 0]}


WPL_HOME = "0\t1\t0\t16\t0\t0\t0\t0\t-35.363261\t149.16523\t584\t1"
WPL_ROW = "1\t0\t3\t16\t0\t0\t0\t0\t-35.3630364\t149.16523\t0\t1"

# (file name, content, substrings the one error line must contain)
CASES = [
    ("syntax.toml", 'name = \n' + CIRCLE, ["not valid TOML", "line 1"]),
    ("unknown_top.toml", 'nme = "x"\n' + CIRCLE, ["nme", "unknown key", "did you mean 'name'"]),
    ("unknown_traj.toml", CIRCLE + "radus = 3\n", ["trajectory.radus", "unknown key"]),
    ("no_traj.toml", 'name = "x"\nduration = 5\n', ["trajectory", "missing"]),
    ("no_kind.toml", "[trajectory]\nradius = 5\n", ["trajectory.kind", "missing"]),
    ("bad_kind.toml", '[trajectory]\nkind = "spiral"\n', ["trajectory.kind", "'spiral'"]),
    ("no_radius.toml", '[trajectory]\nkind = "circle"\nspeed = 1\n',
     ["trajectory.radius", "missing"]),
    ("radius_text.toml", CIRCLE.replace("radius = 5.0", 'radius = "5"'),
     ["trajectory.radius", "'5'"]),
    ("radius_negative.toml", CIRCLE.replace("radius = 5.0", "radius = -3.0"),
     ["trajectory.radius", "-3.0"]),
    ("speed_nan.toml", CIRCLE.replace("speed = 1.0", "speed = nan"),
     ["trajectory.speed", "nan"]),
    ("duration_inf.toml", "duration = inf\n" + CIRCLE, ["duration", "inf"]),
    ("duration_and_laps.toml", "duration = 10\nlaps = 2\n" + CIRCLE, ["laps", "not both"]),
    ("laps_open.toml", 'laps = 2\n[trajectory]\nkind = "line"\nend = [10.0, 0.0]\nspeed = 1\n',
     ["laps", "open"]),
    ("times_backwards.toml", '[trajectory]\nkind = "waypoints"\n'
                             'waypoints = [[0, 0, 0], [10, 5, 0], [10, 5, 5]]\n',
     ["trajectory.waypoints[2]", "10"]),
    ("waypoint_row.toml", '[trajectory]\nkind = "waypoints"\nwaypoints = [[0, 0, 0], [10, 5]]\n',
     ["trajectory.waypoints[1]", "[10, 5]"]),
    ("too_fast.toml", "[limits]\nmax_speed = 2.0\n" + CIRCLE.replace("speed = 1.0", "speed = 3.0"),
     ["limits.max_speed", "3 m/s"]),
    ("tight_timing.toml", '[limits]\nmax_speed = 1.0\n[trajectory]\nkind = "waypoints"\n'
                          'waypoints = [[0, 0, 0], [10, 5, 0], [12, 10, 0], [30, 12, 0]]\n',
     ["between waypoints[1] and [2]", "limits.max_speed"]),
    ("turn_too_fast.toml", "[limits]\nmax_yaw_rate = 0.1\n" + CIRCLE,
     ["limits.max_yaw_rate", "0.2 rad/s"]),
    ("limits_key.toml", "[limits]\nmax_sped = 2\n" + CIRCLE, ["limits.max_sped", "unknown key"]),
    ("limits_zero.toml", "[limits]\nmax_speed = 0\n" + CIRCLE, ["limits.max_speed", "> 0"]),
    ("gains_negative.toml", "[gains.pzc]\nk_dc = -1.0\nlambda_c = 2.0\n" + CIRCLE,
     ["gains", "k_dc", "-1.0"]),
    ("gains_missing_file.toml", 'gains_file = "nowhere.toml"\n' + CIRCLE,
     ["gains_file", "nowhere.toml", "no such file"]),
    ("frame.toml", 'frame = "world"\n' + CIRCLE, ["frame", "'world'"]),
    ("geodetic_no_origin.toml", 'frame = "geodetic"\n' + CIRCLE, ["origin", "missing"]),
    ("origin_range.toml", 'frame = "geodetic"\norigin = [95.0, 10.0]\n' + CIRCLE,
     ["origin", "latitude 95.0"]),
    ("corner.toml", '[trajectory]\nkind = "polyline"\nspeed = 1\ncorner_radius = 5\n'
                    'points = [[0, 0], [10, 0], [10, 3], [0, 3]]\n',
     ["trajectory.corner_radius", "5 m"]),
    ("same_point.toml", '[trajectory]\nkind = "polyline"\nspeed = 1\n'
                        'points = [[0, 0], [10, 0], [10, 0]]\n', ["trajectory.points[2]"]),
    ("reversal.toml", '[trajectory]\nkind = "polyline"\nspeed = 1\n'
                      'points = [[0, 0], [10, 0], [0, 0]]\n',
     ["trajectory.points[1]", "turns back"]),
    ("vehicle.toml", '[vehicle]\nw_c = "fast"\n' + CIRCLE, ["vehicle.w_c", "'fast'"]),
    ("rate_bool.toml", "rate_hz = true\n" + CIRCLE, ["rate_hz", "True"]),
    ("name_number.toml", "name = 5\n" + CIRCLE, ["name", "5"]),
    ("traj_string.toml", 'trajectory = "circle"\n', ["trajectory", "'circle'"]),
    ("points_text.toml", '[trajectory]\nkind = "polyline"\nspeed = 1\n'
                         'points = [[0, 0], [10, "x"]]\n', ["trajectory.points[1][1]", "'x'"]),
    # QGroundControl .plan
    ("json.plan", '{"fileType": "Plan",\n  "mission": [1, 2,]\n}', ["not valid JSON", "line 2"]),
    ("filetype.plan", json.dumps({"fileType": "Fence", "mission": {}}), ["fileType", "'Fence'"]),
    ("no_items.plan", json.dumps({"fileType": "Plan", "mission": {"cruiseSpeed": 1}}),
     ["mission.items", "None"]),
    ("complex.plan", _plan([_wp(), {"type": "ComplexItem", "complexItemType": "survey"}]),
     ["mission.items[1].version", "survey version None"]),
    ("corridor.plan", _plan([_wp(), {"type": "ComplexItem", "complexItemType": "CorridorScan"}]),
     ["mission.items[1]", "'CorridorScan'", "ComplexItem"]),
    ("params.plan", _plan([_wp(params=[0, 0, 0, 5])]), ["mission.items[0].params", "7 numbers"]),
    ("lat_text.plan", _plan([_wp(lat="north")]), ["mission.items[0].params[4]", "'north'"]),
    ("lat_range.plan", _plan([_wp(lat=123.0)]), ["mission.items[0]", "latitude 123.0"]),
    ("no_waypoint.plan", _plan([_wp(command=20)]), ["no NAV_WAYPOINT"]),
    ("cruise.plan", _plan([_wp()], cruiseSpeed=-2), ["mission.cruiseSpeed", "-2"]),
    ("local_frame.plan", _plan([_wp(frame=1)]), ["mission.items[0]", "MAV_FRAME 1"]),
    # QGC WPL 110 .waypoints
    ("header.waypoints", "QGC WPL 100\n" + WPL_HOME + "\n", ["line 1", "QGC WPL 110"]),
    ("fields.waypoints", f"QGC WPL 110\n{WPL_HOME}\n1\t0\t3\t16\t0\t0\n", ["line 3", "found 6"]),
    ("number.waypoints", f"QGC WPL 110\n{WPL_HOME}\n{WPL_ROW.replace('-35.3630364', 'abc')}\n",
     ["line 3", "LAT", "'abc'"]),
    ("index.waypoints", f"QGC WPL 110\n{WPL_HOME}\n{WPL_ROW.replace('1', '5', 1)}\n",
     ["line 3", "INDEX is 5"]),
    # Files that are not there or not missions
    ("missing.toml", None, ["no such file"]),
    ("notes.txt", "hello", ["unknown mission file type", "'.txt'"]),
    ("folder.toml", "<dir>", ["is a directory"]),
]


def test_there_are_at_least_25_malformed_files():
    assert len(CASES) >= 25


def _write(tmp_path: Path, name: str, content: str | None) -> Path:
    path = tmp_path / name
    if content == "<dir>":
        path.mkdir()
    elif content is not None:
        path.write_text(content)
    return path


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """Run `python -m companion mission check FILE` once per case, all processes at once."""
    tmp = tmp_path_factory.mktemp("bad_missions")
    env = dict(os.environ, PYTHONWARNINGS="error")   # a stray warning would be a second line
    procs = {}
    for name, content, _ in CASES:
        path = _write(tmp, name, content)
        procs[name] = (path, subprocess.Popen(
            [sys.executable, "-m", "companion", "mission", "check", str(path)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env))
    out = {}
    for name, (path, proc) in procs.items():
        stdout, stderr = proc.communicate(timeout=120)
        out[name] = (path, proc.returncode, stdout, stderr)
    return out


@pytest.mark.parametrize("name,content,expected", CASES, ids=[c[0] for c in CASES])
def test_malformed_file_gives_one_line_and_exit_code_2(results, name, content, expected):
    path, code, stdout, stderr = results[name]
    assert code == 2, (stdout, stderr)
    assert stdout == ""
    assert "Traceback" not in stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    line = lines[0]
    assert line.startswith("companion mission: error: ")
    assert str(path) in line
    for text in expected:
        assert text in line, (text, line)


def test_check_reports_every_file_and_fails_if_any_is_bad(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text("duration = 20\n" + CIRCLE)
    bad = tmp_path / "bad.toml"
    bad.write_text(CIRCLE.replace("radius = 5.0", "radius = -1.0"))
    proc = companion_cli("mission", "check", str(good),
                         str(bad), timeout=60)
    assert proc.returncode == 2
    assert proc.stdout.count("\n") == 1 and f"{good}: ok: circle" in proc.stdout
    assert "trajectory.radius" in proc.stderr and str(bad) in proc.stderr


def test_loads_gives_the_same_errors_as_load():
    from companion import mission
    from companion.errors import UserError
    with pytest.raises(UserError, match=r"<remote>: trajectory\.radius: must be >= 0\.001, not 0\.0"):
        mission.loads(CIRCLE.replace("radius = 5.0", "radius = 0.0"), "<remote>")
