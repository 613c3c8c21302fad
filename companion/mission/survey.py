"""A QGroundControl Survey (a ``.plan`` ``ComplexItem`` of ``complexItemType`` "survey") as a field.

What QGroundControl writes for a survey (its ``SurveyComplexItem``, ``TransectStyleComplexItem``
and ``CameraCalc``; survey version 4 and 5, transect-style 1 and 2, camera-calc 1 and 2):

* ``polygon``: the area, ``[lat, lon]`` pairs in degrees;
* ``angle``: the transects' heading, degrees clockwise from north;
* ``TransectStyleComplexItem.CameraCalc.AdjustedFootprintSide``: the spacing between transects,
  metres (for a rover: the tool's width less its overlap);
* ``TransectStyleComplexItem.TurnAroundDistance``: metres flown beyond each transect's end to
  turn, outside the polygon;
* ``TransectStyleComplexItem.VisualTransectPoints``: the transects QGroundControl generated,
  ``[lat, lon]``, four points each with a turnaround (in, start, end, out), else two.

A rover flies it as a field (:mod:`companion.mission.field`): the polygon is the swath area (no
headland inside: QGroundControl's transects run to its edges), the turns go at most the
turnaround distance beyond it, and the spacing and angle are the survey's. QGroundControl's own
transects are the check: :func:`compare` says how far the planned swaths lie from them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from .schema import check_number, fail, short

SURVEY_VERSIONS = (4, 5)          # older ones kept a "grid" object: re-save in QGroundControl


@dataclass(frozen=True)
class Survey:
    """A survey as read, in degrees and metres."""

    where: str                                  # "mission.items[1]"
    index: int                                  # 1: its place in the file's items
    polygon: tuple[tuple[float, float], ...]    # (lat, lon)
    angle_deg: float
    spacing: float
    turnaround: float
    transects: tuple[tuple[tuple[float, float], tuple[float, float]], ...]   # (lat, lon) pairs


def parse(item: dict[str, Any], source: str, where: str, index: int) -> Survey:
    """A survey ComplexItem, every problem a one-line error naming the key."""
    version = item.get("version")
    if version not in SURVEY_VERSIONS:
        raise fail(source, f"{where}.version", (
            f"survey version {short(version)} is not read (versions "
            f"{', '.join(map(str, SURVEY_VERSIONS))}): open and save the plan in a current "
            "QGroundControl"))
    polygon = _points(item.get("polygon"), source, f"{where}.polygon", 3)
    angle = check_number(item.get("angle"), source, f"{where}.angle", minimum=-360.0,
                         maximum=360.0)
    transect = item.get("TransectStyleComplexItem")
    tw = f"{where}.TransectStyleComplexItem"
    if not isinstance(transect, dict):
        raise fail(source, tw, f"must be an object, not {short(transect)}")
    camera = transect.get("CameraCalc")
    if not isinstance(camera, dict):
        raise fail(source, f"{tw}.CameraCalc", f"must be an object, not {short(camera)}")
    spacing = check_number(camera.get("AdjustedFootprintSide"), source,
                           f"{tw}.CameraCalc.AdjustedFootprintSide", positive=True,
                           maximum=1000.0)
    turnaround = check_number(transect.get("TurnAroundDistance", 0.0), source,
                              f"{tw}.TurnAroundDistance", minimum=0.0, maximum=1000.0)
    visual = _points(transect.get("VisualTransectPoints", []), source,
                     f"{tw}.VisualTransectPoints", 0)
    group = 4 if turnaround > 0 and len(visual) % 4 == 0 else 2
    if len(visual) % group:
        raise fail(source, f"{tw}.VisualTransectPoints",
                   f"holds {len(visual)} points, not whole transects of {group}")
    inner = (1, 2) if group == 4 else (0, 1)
    transects = tuple((visual[k + inner[0]], visual[k + inner[1]])
                      for k in range(0, len(visual), group))
    return Survey(where, index, polygon, float(angle), float(spacing), float(turnaround), transects)


def _points(value: Any, source: str, path: str, least: int) -> tuple[tuple[float, float], ...]:
    from . import geo
    if not isinstance(value, list) or len(value) < least:
        raise fail(source, path, f"must be a list of at least {least} [lat, lon] points, not "
                                 f"{short(value)}")
    out = []
    for i, p in enumerate(value):
        if not isinstance(p, list) or len(p) < 2:
            raise fail(source, f"{path}[{i}]", f"must be [lat, lon], not {short(p)}")
        lat = check_number(p[0], source, f"{path}[{i}][0]")
        lon = check_number(p[1], source, f"{path}[{i}][1]")
        problem = geo.check_latlon(lat, lon)
        if problem:
            raise fail(source, f"{path}[{i}]", problem)
        out.append((float(lat), float(lon)))
    return tuple(out)


def compare(swaths, transects, spacing: float) -> tuple[str, bool]:
    """How the planned ``swaths`` lie against QGroundControl's ``transects`` (both as local
    ((north, east), (north, east)) pairs), in one line, and whether they agree: as many, and
    none more than a tenth of the ``spacing`` to the side of the nearest swath line."""
    if not transects:
        return "the file holds no transects of its own to compare", True
    worst = 0.0
    for (a, b) in transects:
        mid = ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)
        worst = max(worst, min(_offset(mid, p, q) for p, q in swaths))
    agree = len(transects) == len(swaths) and worst <= 0.1 * spacing
    return (f"QGroundControl's {len(transects)} transects against {len(swaths)} swaths here: "
            f"the farthest {worst:.2f} m to the side of the nearest swath", agree)


def _offset(point, p, q) -> float:
    """Distance of ``point`` from the infinite line through p and q."""
    dx, dy = q[0] - p[0], q[1] - p[1]
    length = math.hypot(dx, dy)
    if length == 0:
        return math.dist(point, p)
    return abs((point[0] - p[0]) * dy - (point[1] - p[1]) * dx) / length
