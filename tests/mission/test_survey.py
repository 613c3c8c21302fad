"""A QGroundControl Survey ``.plan`` (a real one, saved by QGroundControl: missions/qgc/) is
flown as a field: its polygon, angle, spacing and turnaround planned here, its own transects
the check; what cannot be flown is a one-line error."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from shapely.geometry import LineString, Point, Polygon

from companion import mission as missions
from companion.errors import UserError
from companion.mission import geo, plan_import
from testbed.process import companion_cli

ROOT = Path(__file__).resolve().parents[2]
SURVEY = ROOT / "missions" / "qgc" / "mavsdk_survey.plan"


def test_the_survey_is_read_as_qgroundcontrol_wrote_it():
    plan = plan_import.read(SURVEY)
    sv = plan.survey
    assert sv is not None and sv.where == "mission.items[1]"
    assert (sv.angle_deg, sv.spacing, sv.turnaround) == (90.0, 25.0, 10.0)
    assert len(sv.polygon) == 4 and len(sv.transects) == 2
    assert any("SET_CAMERA_MODE" in w for w in plan.warnings)


def test_the_swaths_planned_here_lie_on_qgroundcontrols_transects():
    m = missions.load(SURVEY, speed=1.0)
    plan = plan_import.read(SURVEY)
    origin = m.datum
    assert origin is not None

    def local(p):
        return geo.ne_from_latlon(p[0], p[1], origin)

    straights = [LineString(s) for s in m.trajectory.straights()]
    for a, b in plan.survey.transects:
        qgc = LineString([local(a), local(b)])
        # each transect is driven on a straight, to within 0.1 m (the geodesy of two programs)
        assert any(st.buffer(0.1).contains(qgc) for st in straights), qgc
    # the turns stay within the turnaround distance of the polygon
    area = Polygon([local(p) for p in plan.survey.polygon])
    room = area.buffer(10.0 + 0.01)
    outline = m.trajectory.outline()
    first_in = next(i for i, p in enumerate(outline) if room.contains(Point(p)))
    assert first_in < len(outline) // 10          # only the lead-in from home is outside
    assert room.contains(LineString(outline[first_in:]))
    assert not any("transects against" in w for w in m.warnings)   # they agree: no warning
    assert "QGroundControl's 2 transects against 2 swaths" in m.description


def test_the_shipped_survey_mission_checks():
    proc = companion_cli("mission", "check", "missions/qgc_survey.toml", timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "survey" in proc.stdout and "2 swaths at 25 m" in proc.stdout


def _survey_plan(tmp_path, **change):
    data = json.loads(SURVEY.read_text())
    item = data["mission"]["items"][1]
    for key, value in change.items():
        if key == "extra":
            data["mission"]["items"].append(value)
        elif key == "spacing":
            item["TransectStyleComplexItem"]["CameraCalc"]["AdjustedFootprintSide"] = value
        else:
            item[key] = value
    path = tmp_path / "s.plan"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize("change,text", [
    ({"version": 9}, "mission.items[1].version"),
    ({"spacing": -5}, "AdjustedFootprintSide"),
    ({"polygon": [[47.39, 8.54]]}, "mission.items[1].polygon"),
    ({"angle": "east"}, "mission.items[1].angle"),
    ({"extra": {"type": "ComplexItem", "complexItemType": "survey", "version": 5}},
     "a second survey"),
])
def test_a_survey_it_cannot_fly_is_a_one_line_error(tmp_path, change, text):
    path = _survey_plan(tmp_path, **change)
    with pytest.raises(UserError) as err:
        missions.load(path, speed=1.0)
    line = str(err.value)
    assert "\n" not in line and str(path) in line and text in line, line


def test_waypoints_before_and_after_lead_to_the_survey_and_on(tmp_path):
    home = json.loads(SURVEY.read_text())["mission"]["plannedHomePosition"]
    after = geo.latlon_from_ne(-80.0, 20.0, (home[0], home[1]))
    wp = {"type": "SimpleItem", "command": 16, "frame": 3, "autoContinue": True,
          "doJumpId": 9, "params": [0, 0, 0, None, after[0], after[1], 5]}
    path = _survey_plan(tmp_path, extra=wp)
    m = missions.load(path, speed=1.0)
    end = m.trajectory.sample(m.duration)
    assert math.hypot(end.x + 80.0, end.y - 20.0) < 0.01      # ends at the last waypoint
    start = m.trajectory.sample(0.0)
    assert math.hypot(start.x, start.y) < 0.01                  # starts at home
