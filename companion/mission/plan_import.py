"""Read the mission files users already have: QGroundControl ``.plan`` and ``QGC WPL 110``.

Both become an :class:`ImportedPlan`: the points of the path in local (north, east) metres,
converted exactly as ArduPilot does (:mod:`companion.mission.geo`) around the EKF origin, or around the
plan's home when no origin is given (simulation). The path starts at home, where a rover sits
when it starts a mission, and visits every ``MAV_CMD_NAV_WAYPOINT`` (16) in order;
:mod:`companion.mission` rounds its corners and drives it at the cruise speed.

Items policy (documented in docs/missions.md): an item the tracker cannot follow is *reported*, one
warning line per item (``ImportedPlan.warnings``), and left out of the path: takeoff, land,
loiter, return-to-launch, jumps, camera and other DO commands, a waypoint's hold time, a waypoint
at the same place as the previous point. The first ``DO_CHANGE_SPEED`` before any waypoint sets
the speed (later ones are reported). A QGroundControl Survey (a ComplexItem) is read by
:mod:`companion.mission.survey` and flown as a field, the waypoints before it leading there
and those after it leading on; a plan holds one survey. What cannot be turned into a path at
all is an *error*: other ComplexItems (corridor and structure scans), a waypoint without a
position or in a local frame, a malformed file.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import UserError
from . import geo
from .schema import check_number, fail, short
from .survey import Survey

NAV_WAYPOINT = 16
DO_CHANGE_SPEED = 178
DEFAULT_SPEED = 2.0        # m/s: ArduPilot Rover's WP_SPEED default, when a file gives none
GLOBAL_FRAMES = {0, 3, 5, 6, 10, 11}   # MAV_FRAME_GLOBAL*, *_INT, *_TERRAIN_ALT*: lat/lon items

COMMAND_NAMES = {
    16: "NAV_WAYPOINT", 17: "NAV_LOITER_UNLIM", 18: "NAV_LOITER_TURNS", 19: "NAV_LOITER_TIME",
    20: "NAV_RETURN_TO_LAUNCH", 21: "NAV_LAND", 22: "NAV_TAKEOFF", 31: "NAV_LOITER_TO_ALT",
    82: "NAV_SPLINE_WAYPOINT", 93: "NAV_DELAY", 112: "CONDITION_DELAY",
    114: "CONDITION_DISTANCE", 115: "CONDITION_YAW", 177: "DO_JUMP", 178: "DO_CHANGE_SPEED",
    179: "DO_SET_HOME", 181: "DO_SET_RELAY", 183: "DO_SET_SERVO", 201: "DO_SET_ROI",
    203: "DO_DIGICAM_CONTROL", 206: "DO_SET_CAM_TRIGG_DIST", 530: "SET_CAMERA_MODE",
    2000: "IMAGE_START_CAPTURE", 2001: "IMAGE_STOP_CAPTURE",
}


@dataclass(frozen=True)
class ImportedPlan:
    points: tuple[tuple[float, float], ...]   # local (north, east), home first
    speed: float | None                       # m/s from the file (cruise / DO_CHANGE_SPEED)
    origin: tuple[float, float]               # (lat, lon) the points are relative to
    home: tuple[float, float] | None
    waypoint_count: int
    warnings: tuple[str, ...]
    survey: Survey | None = None                # a QGroundControl Survey: flown as a field
    survey_at: int = 0                          # points[:survey_at] lead to it, the rest after


@dataclass(frozen=True)
class _Item:
    where: str            # "mission.items[3]" or "line 5"
    command: int
    frame: int
    params: tuple[float, ...]   # p1..p4, lat, lon, alt (NaN where the file has null)
    index: int = -1             # place in the file's item list


def read(path: str | Path, origin: tuple[float, float] | None = None) -> ImportedPlan:
    """Read a ``.plan`` or ``.waypoints`` file (chosen by suffix)."""
    path = Path(path)
    text = _read_text(path)
    survey = None
    if path.suffix.lower() == ".plan":
        home, speed, items, survey = _parse_plan(text, str(path))
    else:
        home, speed, items = _parse_wpl(text, str(path))
    return _build(str(path), home, speed, items, origin, survey)


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise UserError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise UserError(f"{path}: is a directory, not a mission file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{path}: cannot read: {exc}") from None


def _name(command: int) -> str:
    return f"{COMMAND_NAMES.get(command, 'MAV_CMD')} ({command})"


# --------------------------------------------------------------------------- QGC .plan (JSON)


def _parse_plan(text: str, source: str):
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise UserError(f"{source}: not valid JSON: {exc}") from None
    except RecursionError:
        raise UserError(f"{source}: not valid JSON: nested too deeply") from None
    if not isinstance(data, dict):
        raise fail(source, "", f"a .plan file must hold a JSON object, not {short(data)}")
    if data.get("fileType") != "Plan":
        raise fail(source, "fileType", f"must be \"Plan\", not {short(data.get('fileType'))}")
    mission = data.get("mission")
    if not isinstance(mission, dict):
        raise fail(source, "mission", f"must be an object, not {short(mission)}")

    home = None
    if "plannedHomePosition" in mission:
        value = mission["plannedHomePosition"]
        if not isinstance(value, list) or len(value) < 2:
            raise fail(source, "mission.plannedHomePosition",
                       f"must be [lat, lon, alt], not {short(value)}")
        lat = check_number(value[0], source, "mission.plannedHomePosition[0]")
        lon = check_number(value[1], source, "mission.plannedHomePosition[1]")
        problem = geo.check_latlon(lat, lon)
        if problem:
            raise fail(source, "mission.plannedHomePosition", problem)
        # 0, 0 is an autopilot's home before its first GPS fix (ArduPilot's mission item 0):
        # unset, as in a .waypoints file, not a point 16 000 km off to start from
        home = None if (lat, lon) == (0.0, 0.0) else (lat, lon)

    speed = None
    if "cruiseSpeed" in mission and mission["cruiseSpeed"] is not None:
        speed = check_number(mission["cruiseSpeed"], source, "mission.cruiseSpeed",
                             positive=True, maximum=100.0)

    items_value = mission.get("items")
    if not isinstance(items_value, list):
        raise fail(source, "mission.items", f"must be a list of items, not {short(items_value)}")
    items = []
    survey = None
    for i, item in enumerate(items_value):
        where = f"mission.items[{i}]"
        if not isinstance(item, dict):
            raise fail(source, where, f"must be an object, not {short(item)}")
        kind = item.get("type")
        if kind == "ComplexItem" and item.get("complexItemType") == "survey":
            if survey is not None:
                raise fail(source, where, f"a second survey (the first is {survey.where}): "
                                          "a plan holds one field; save each in its own plan")
            from . import survey as surveys
            survey = surveys.parse(item, source, where, i)
            continue
        if kind == "ComplexItem":
            what = item.get("complexItemType", "a complex item")
            raise fail(source, where, (
                f"{short(what)} is a ComplexItem this companion does not fly (a survey it "
                "does); convert it to waypoints in QGroundControl first"))
        if kind != "SimpleItem":
            raise fail(source, f"{where}.type",
                       f"must be \"SimpleItem\" or \"ComplexItem\", not {short(kind)}")
        command = _integer(item.get("command"), source, f"{where}.command")
        frame = _integer(item.get("frame", 0), source, f"{where}.frame")
        params = item.get("params")
        if not isinstance(params, list) or len(params) != 7:
            raise fail(source, f"{where}.params",
                       f"must be 7 numbers [p1, p2, p3, p4, lat, lon, alt], not {short(params)}")
        values = []
        for k, p in enumerate(params):
            # QGroundControl writes null for an unused parameter (NaN in MAVLink).
            values.append(math.nan if p is None else
                          check_number(p, source, f"{where}.params[{k}]"))
        items.append(_Item(where, command, frame, tuple(values), i))
    return home, speed, items, survey


def _integer(value: Any, source: str, path: str) -> int:
    number = check_number(value, source, path, minimum=0, maximum=65535)
    if number != int(number):
        raise fail(source, path, f"must be a whole number, not {short(value)}")
    return int(number)


# --------------------------------------------------------------------------- QGC WPL 110


def _parse_wpl(text: str, source: str):
    lines = text.splitlines()
    if not lines or not lines[0].strip().startswith("QGC WPL 110"):
        first = lines[0].strip() if lines else ""
        raise UserError(f"{source}: line 1: expected 'QGC WPL 110', found {short(first)}")
    home = None
    items = []
    expected = 0
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        where = f"line {number}"
        fields = line.split("\t") if "\t" in line else line.split()
        fields = [f.strip() for f in fields]
        if len(fields) != 12:
            raise UserError(f"{source}: {where}: expected 12 tab-separated fields (INDEX CURRENT "
                            f"FRAME COMMAND P1 P2 P3 P4 LAT LON ALT AUTOCONTINUE), found "
                            f"{len(fields)}")
        names = ("INDEX", "CURRENT", "FRAME", "COMMAND", "P1", "P2", "P3", "P4", "LAT", "LON",
                 "ALT", "AUTOCONTINUE")
        values = []
        for name, field in zip(names, fields, strict=True):
            try:
                value = float(field)
            except ValueError:
                raise UserError(f"{source}: {where}: {name} must be a number, not "
                                f"{short(field)}") from None
            if not math.isfinite(value):
                raise UserError(f"{source}: {where}: {name} must be finite, not {short(field)}")
            values.append(value)
        index, _current, frame, command = values[:4]
        for name, value in (("INDEX", index), ("FRAME", frame), ("COMMAND", command)):
            if value != int(value) or value < 0:
                raise UserError(f"{source}: {where}: {name} must be a whole number, not "
                                f"{short(fields[names.index(name)])}")
        if int(index) != expected:
            raise UserError(f"{source}: {where}: INDEX is {int(index)}, expected {expected}")
        expected += 1
        if index == 0:
            # Row 0 is the home position (Mission Planner's convention); 0, 0 means unset.
            lat, lon = values[8], values[9]
            if (lat, lon) != (0.0, 0.0):
                problem = geo.check_latlon(lat, lon)
                if problem:
                    raise UserError(f"{source}: {where}: home {problem}")
                home = (lat, lon)
            continue
        items.append(_Item(where, int(command), int(frame), tuple(values[4:11])))
    return home, None, items


# --------------------------------------------------------------------------- to a path


def _build(source: str, home, speed, items: list[_Item],
           origin: tuple[float, float] | None, survey: Survey | None = None) -> ImportedPlan:
    if origin is None:
        if home is None:
            raise UserError(f"{source}: the file has no home position; give the vehicle's EKF "
                            "origin (lat, lon) to place it")
        origin = home
    else:
        problem = geo.check_latlon(*origin)
        if problem:
            raise UserError(f"{source}: EKF origin {problem}")
    warnings: list[str] = []
    points: list[tuple[float, float]] = []
    if home is not None:
        points.append(geo.ne_from_latlon(home[0], home[1], origin))
    count = 0
    survey_at = None
    for item in items:
        if survey is not None and survey_at is None and item.index > survey.index:
            survey_at = len(points)
        p1, p2 = item.params[0], item.params[1]
        if item.command == DO_CHANGE_SPEED:
            if count == 0 and math.isfinite(p2) and p2 > 0 and speed is None:
                speed = min(p2, 100.0)
            else:
                warnings.append(f"{source}: {item.where}: {_name(item.command)} is ignored: the "
                                "whole path runs at one speed")
            continue
        if item.command != NAV_WAYPOINT:
            warnings.append(f"{source}: {item.where}: {_name(item.command)} is not followed: "
                            + ("the survey makes the path" if survey is not None else
                               "only NAV_WAYPOINT items make the path"))
            continue
        if item.frame not in GLOBAL_FRAMES:
            raise UserError(f"{source}: {item.where}: NAV_WAYPOINT in MAV_FRAME {item.frame}: "
                            "only global (lat/lon) frames are supported")
        lat, lon = item.params[4], item.params[5]
        if not (math.isfinite(lat) and math.isfinite(lon)) or (lat, lon) == (0.0, 0.0):
            raise UserError(f"{source}: {item.where}: NAV_WAYPOINT has no position "
                            f"(lat {lat!r}, lon {lon!r})")
        problem = geo.check_latlon(lat, lon)
        if problem:
            raise UserError(f"{source}: {item.where}: {problem}")
        count += 1
        if math.isfinite(p1) and p1 > 0:
            warnings.append(f"{source}: {item.where}: hold time {p1:g} s is not held: the path "
                            "passes through without stopping")
        point = geo.ne_from_latlon(lat, lon, origin)
        if points and math.dist(point, points[-1]) < 0.01:
            warnings.append(f"{source}: {item.where}: NAV_WAYPOINT at the same place as the "
                            "previous point, skipped")
            continue
        points.append(point)
    if survey is not None:
        return ImportedPlan(tuple(points), speed, origin, home, count, tuple(warnings), survey,
                            len(points) if survey_at is None else survey_at)
    if count == 0:
        raise UserError(f"{source}: no NAV_WAYPOINT items: there is no path to follow")
    if len(points) < 2:
        raise UserError(f"{source}: the path has a single point: nothing to follow")
    return ImportedPlan(tuple(points), speed, origin, home, count, tuple(warnings))
