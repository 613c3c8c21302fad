"""How a field was driven, from true positions (issue 45): cross-track error on the swaths,
excursion beyond the boundary, the share of the swath area missed at a tool width. One scoring
for any driver (the companion, ArduPilot's own AUTO), from positions alone: a sample counts on
a swath when its projection falls inside the swath's interior (``margin`` from each end) and
it lies within half a spacing of that swath's line."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from shapely import LineString, Point, Polygon

Pt = tuple[float, float]


def cross_track(points: Sequence[Pt], swaths: Sequence[tuple[Pt, Pt]], spacing: float,
                margin: float = 1.0, signed: bool = False) -> np.ndarray:
    """The distance to the side of its swath of every sample on a swath interior (m); with
    ``signed``, (swath index, signed distance: + to the right of the swath as driven)."""
    lines = [LineString(s) for s in swaths]
    out = []
    for p in points:
        pt = Point(p)
        best = None
        for k, line in enumerate(lines):
            at = line.project(pt)
            if margin <= at <= line.length - margin:
                d = line.distance(pt)
                if d < 0.5 * spacing and (best is None or d < best[1]):
                    best = (k, d)
        if best is not None:
            if not signed:
                out.append(best[1])
                continue
            (ax, ay), (bx, by) = swaths[best[0]]
            length = float(np.hypot(bx - ax, by - ay))
            # north-east axes: (b - a) x (p - a) > 0 is to the right of the way driven
            side = ((bx - ax) * (p[1] - ay) - (by - ay) * (p[0] - ax)) / length
            out.append((best[0], side))
    return np.array(out)


def excursion(points: Sequence[Pt], boundary: Sequence[Pt]) -> float:
    """The farthest any sample went outside ``boundary`` (m; 0 inside)."""
    field = Polygon(boundary)
    return max((field.exterior.distance(Point(p)) for p in points
                if not field.contains(Point(p))), default=0.0)


def missed_share(points: Sequence[Pt], area: Polygon, tool_width: float) -> float:
    """The share of ``area`` a tool ``tool_width`` wide, carried along ``points``, never
    passed over."""
    swept = LineString(points).buffer(tool_width / 2.0)
    return float(area.difference(swept).area / area.area)


def figures(points: Sequence[Pt], swaths: Sequence[tuple[Pt, Pt]], spacing: float,
            boundary: Sequence[Pt], area: Polygon) -> dict:
    """The benchmark's row: cross-track p50 / p95 / max, samples on swaths, excursion, and
    the share missed at the spacing + 0.1 m."""
    xt = cross_track(points, swaths, spacing)
    return {"cross_p50": float(np.percentile(xt, 50)) if len(xt) else float("nan"),
            "cross_p95": float(np.percentile(xt, 95)) if len(xt) else float("nan"),
            "cross_max": float(xt.max()) if len(xt) else float("nan"),
            "on_swaths": int(len(xt)), "samples": len(points),
            "bias_even_odd": _bias(points, swaths, spacing),
            "excursion": excursion(points, boundary),
            "missed": missed_share(points, area, spacing + 0.1)}



def _bias(points, swaths, spacing: float) -> list[float]:
    """The mean signed cross-track on the swaths driven one way and on those driven back: equal
    and opposite means a constant offset of the positions (the truth's origin against the
    estimate's), equal a lean of the tracking."""
    signed = cross_track(points, swaths, spacing, signed=True)
    if not len(signed):
        return [float("nan"), float("nan")]
    even = signed[signed[:, 0] % 2 == 0, 1]
    odd = signed[signed[:, 0] % 2 == 1, 1]
    return [float(even.mean()) if len(even) else float("nan"),
            float(odd.mean()) if len(odd) else float("nan")]
