"""How a field was covered, from the positions a rover took (issue 45): cross-track error on the
swaths, excursion beyond the boundary, the share of the swath area missed at a tool width.

One scoring for any driver (the companion, an autopilot's own AUTO) and any positions (the
estimate a run logged, a simulator's truth), from positions alone: a sample counts on a swath
when its projection falls inside the swath's interior (``margin`` from each end) and it lies
within half a spacing of that swath's line. Geometry by shapely. Pure: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

Pt = tuple[float, float]
MARGIN = 1.0          # m at each swath end not scored: where the turn's transient lives


@dataclass(frozen=True)
class FieldCover:
    """What a field's route is meant to cover, in the mission's frame: its swaths as driven,
    their spacing, and the swath area (the field less its headland) and the boundary."""

    swaths: tuple[tuple[Pt, Pt], ...]
    spacing: float
    area: tuple[Pt, ...]
    boundary: tuple[Pt, ...]

    def placed(self, x: float, y: float, yaw: float) -> FieldCover:
        """The same turned by ``yaw`` and moved to (x, y) (a "start"-frame mission anchored
        where the rover began, as ``companion.mission.paths.Placed``)."""
        c, s = math.cos(yaw), math.sin(yaw)

        def move(p: Pt) -> Pt:
            return (x + c * p[0] - s * p[1], y + s * p[0] + c * p[1])
        return FieldCover(tuple((move(a), move(b)) for a, b in self.swaths), self.spacing,
                          tuple(move(p) for p in self.area), tuple(move(p) for p in self.boundary))


def cross_track(points: Sequence[Pt], swaths: Sequence[tuple[Pt, Pt]], spacing: float,
                margin: float = MARGIN) -> np.ndarray:
    """Each sample on a swath interior as (swath index, signed distance: + to the right of the
    swath as driven, m); shape (n, 2). Vectorised over samples, one swath at a time."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    best = np.full(len(p), np.inf)
    which = np.full(len(p), -1)
    side_of = np.zeros(len(p))
    for k, (a, b) in enumerate(swaths):
        d = np.subtract(b, a)
        length = float(np.hypot(*d))
        u = d / length
        rel = p - np.asarray(a)
        along = rel @ u
        # north-east axes: u x rel > 0 is to the right of the way driven
        side = u[0] * rel[:, 1] - u[1] * rel[:, 0]
        inside = (along >= margin) & (along <= length - margin) & (np.abs(side) < 0.5 * spacing)
        better = inside & (np.abs(side) < best)
        best[better], which[better], side_of[better] = np.abs(side[better]), k, side[better]
    on = which >= 0
    return np.column_stack([which[on], side_of[on]])


def excursion(points: Sequence[Pt], boundary: Sequence[Pt]) -> float:
    """The farthest any sample went outside ``boundary`` (m; 0 inside)."""
    from shapely import Point, Polygon
    field = Polygon(boundary)
    return max((field.exterior.distance(Point(p)) for p in points
                if not field.contains(Point(p))), default=0.0)


def missed_share(points: Sequence[Pt], area: Sequence[Pt], tool_width: float) -> float:
    """The share of ``area`` a tool ``tool_width`` wide, carried along ``points``, never
    passed over."""
    from shapely import LineString, Polygon
    region = Polygon(area)
    if len(points) < 2:
        return 1.0
    swept = LineString(points).buffer(tool_width / 2.0)
    return float(region.difference(swept).area / region.area)


def figures(points: Sequence[Pt], cover: FieldCover, tool_width: float | None = None) -> dict:
    """Cross-track p50 / p95 / max over the swath interiors, the mean to the right of the
    swaths driven out and of those driven back (equal and opposite: the positions are offset;
    equal: the tracking leans), samples on swaths of all, the excursion beyond the boundary,
    and the share of the swath area missed by a tool ``tool_width`` wide (default: the
    spacing)."""
    tool = tool_width or cover.spacing
    signed = cross_track(points, cover.swaths, cover.spacing)
    xt = np.abs(signed[:, 1])
    out_back = [signed[signed[:, 0] % 2 == k, 1] for k in (0, 1)]

    def stat(v: np.ndarray, f) -> float | None:
        return float(f(v)) if len(v) else None
    return {"swaths": len(cover.swaths),
            "cross_track_p50": stat(xt, lambda v: np.percentile(v, 50)),
            "cross_track_p95": stat(xt, lambda v: np.percentile(v, 95)),
            "cross_track_max": stat(xt, np.max),
            "lean_out_back": [stat(v, np.mean) for v in out_back],
            "on_swaths": int(len(xt)), "samples": len(points),
            "excursion": excursion(points, cover.boundary),
            "tool_width": tool, "missed": missed_share(points, cover.area, tool)}
