"""Helpers for the tests of missions placed by latitude / longitude: a QGroundControl .plan
written around a home, points moved by metres, and how close a vehicle's own
GLOBAL_POSITION_INT came to each waypoint.

The metres <-> degrees conversion here is a plain spherical-earth one, written independently of
``companion.mission.geo`` (which the code under test uses): over the few tens of metres of these
plans the two agree to millimetres, so a test cannot pass by sharing the code's mistake.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

EARTH_RADIUS = 6378100.0      # m (the radius ArduPilot's constant is made from)
CMAC = (-35.363261, 149.165230)   # ArduPilot SITL's default home; example_rover.plan's home

# A plan for the tests: gentle bends (20-30 degrees), so a path with 2 m corner arcs passes
# within 0.1 m of every waypoint and a vehicle passing one more than 1 m away is not on it.
# (north, east) metres from home; the first leg runs south.
GENTLE_WAYPOINTS = ((-20.0, 0.0), (-35.0, 8.0), (-45.0, 22.0), (-50.0, 40.0))


def moved(point: tuple[float, float], north: float, east: float) -> tuple[float, float]:
    """(lat, lon) ``north`` / ``east`` metres from ``point``."""
    lat, lon = point
    dlat = math.degrees(north / EARTH_RADIUS)
    dlon = math.degrees(east / (EARTH_RADIUS * math.cos(math.radians(lat))))
    return lat + dlat, lon + dlon


def metres_between(a: tuple[float, float], b: tuple[float, float]) -> float:
    north = math.radians(a[0] - b[0]) * EARTH_RADIUS
    east = (math.radians(a[1] - b[1]) * EARTH_RADIUS
            * math.cos(math.radians((a[0] + b[0]) / 2)))
    return math.hypot(north, east)


def write_plan(path: Path, home: tuple[float, float], offsets=GENTLE_WAYPOINTS,
               speed: float = 1.5) -> list[tuple[float, float]]:
    """A QGroundControl .plan: home, then one NAV_WAYPOINT per (north, east) offset from home.
    Returns the waypoints' (lat, lon)."""
    points = [moved(home, n, e) for n, e in offsets]
    items = [{"type": "SimpleItem", "command": 16, "frame": 3, "autoContinue": True,
              "doJumpId": i + 1, "params": [0, 0, 0, None, round(lat, 7), round(lon, 7), 0]}
             for i, (lat, lon) in enumerate(points)]
    plan = {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
            "mission": {"cruiseSpeed": speed, "firmwareType": 3, "vehicleType": 10,
                        "version": 2, "items": items,
                        "plannedHomePosition": [round(home[0], 7), round(home[1], 7), 584]},
            "geoFence": {"circles": [], "polygons": [], "version": 2},
            "rallyPoints": {"points": [], "version": 2}}
    path.write_text(json.dumps(plan, indent=1))
    return [(round(lat, 7), round(lon, 7)) for lat, lon in points]


def plan_waypoints(path: Path) -> list[tuple[float, float]]:
    """The NAV_WAYPOINT (lat, lon) of a .plan file, read straight from its JSON."""
    items = json.loads(Path(path).read_text())["mission"]["items"]
    return [(it["params"][4], it["params"][5]) for it in items if it["command"] == 16]


def closest_approaches(global_positions: Iterable[Any],
                       waypoints: list[tuple[float, float]]) -> list[float]:
    """For each waypoint, the least distance (m) of any GLOBAL_POSITION_INT to it."""
    fixes = [(m.lat * 1e-7, m.lon * 1e-7) for m in global_positions]
    assert fixes, "no GLOBAL_POSITION_INT from the vehicle"
    return [min(metres_between(f, wp) for f in fixes) for wp in waypoints]


def path_distances(plan: Path, waypoints: list[tuple[float, float]]) -> list[float]:
    """How close the companion's reference path itself passes each waypoint (m): its corners
    are arcs of up to 2 m radius, so a sharp corner is passed inside, by design."""
    from companion import mission as missions
    from companion.mission import geo
    m = missions.load(plan)          # around the plan's home
    refs = [m.trajectory.sample(m.duration * k / 4000) for k in range(4001)]
    out = []
    for wp in waypoints:
        north, east = geo.ne_from_latlon(*wp, m.datum)
        out.append(min(math.hypot(r.x - north, r.y - east) for r in refs))
    return out
