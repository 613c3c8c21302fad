"""Fields: a boundary polygon covered by parallel swaths, joined by turns inside the headland.

The geometry is shapely's (offsets, clipping, the minimum rotated rectangle); nothing here
hand-writes polygon maths. Coordinates are (north, east) metres; a swath heading is radians
from north towards east.

* The **swath area** is the field shrunk by its ``headland`` (a negative buffer, mitred corners).
* **Swaths** are lines at ``spacing`` apart across it, heading ``angle`` (None: along the long
  side of the swath area's minimum rotated rectangle, the fewest swaths and turns), centred so
  the outer swaths lie spacing / 2 or less inside its edges: with a tool of the spacing's width
  they reach the edges. Each is the line's part inside the swath area; a line cut in two (a
  concave field, a hole) is refused, since joining the parts would cross what is not field; a
  part shorter than the spacing (a corner's sliver) is left out and counted.
* The **route** drives the swaths in turn, alternating direction, each extended by the turn
  radius into the headland so the turn between two swaths (two arcs of the radius, at most
  spacing / 2 and at most the ``turn_room``, joined by the connecting side) begins after the
  swath's end: :class:`~companion.mission.route.Route`, at the straight speed on the swaths and
  the speed the turn allows in the turns.
* ``turn_room`` is how far beyond the swath area the turns may go: the headland for a field with
  one, a QGroundControl survey's turnaround distance for a survey (whose transects run to the
  polygon's edges). The route is checked to stay within the swath area grown by it.

Not yet here (docs/missions.md): headland passes, holes, concave fields, Ackermann turns wider
than the spacing (bulb or three-point turns), reversing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from .coverage import FieldCover
from .paths import PathError
from .route import Route, RouteLimits

MAX_SWATHS = 5000          # a field of 5 km at 1 m spacing; bounds planning time
EDGE = 1e-6                # m: numerical slack for "on the boundary"


@dataclass(frozen=True)
class FieldPlan:
    """A field's swaths and the route that drives them."""

    route: Route
    swaths: tuple[tuple[tuple[float, float], tuple[float, float]], ...]   # as driven
    angle: float               # swath heading, radians from north towards east
    spacing: float
    turn_radius: float
    covered: float             # share of the swath area the swaths cover at the spacing's width


def plan(boundary: Sequence[tuple[float, float]], *, spacing: float, limits: RouteLimits,
         angle: float | None = None, headland: float = 0.0, turn_room: float | None = None,
         start: tuple[float, float] | None = None, kind: str = "field",
         lead_in: Sequence[tuple[float, float]] = (),
         lead_out: Sequence[tuple[float, float]] = (),
         through: tuple[float, float] | None = None) -> FieldPlan:
    """The swaths and route of a field (see the module docstring), entered at the corner
    nearest ``start`` (None: the first swath, driven along the heading); the route drives
    ``lead_in`` before it and ``lead_out`` after (a plan's waypoints around its survey). With
    ``through``, the swath lines are placed so one passes through that point (a survey's own
    transects), not centred. A problem is a :class:`PathError` naming the key."""
    from shapely import affinity
    from shapely.geometry import LineString, Point, Polygon
    from shapely.ops import unary_union
    from shapely.validation import explain_validity

    if not (math.isfinite(spacing) and spacing > 0):
        raise PathError("spacing", f"must be a positive number of metres, not {spacing!r}")
    if not (math.isfinite(headland) and headland >= 0):
        raise PathError("headland", f"must be 0 or more metres, not {headland!r}")
    room = headland if turn_room is None else turn_room
    if len(boundary) < 3:
        raise PathError("boundary", f"needs at least 3 points, has {len(boundary)}")
    field = Polygon(boundary)
    if not field.is_valid:
        raise PathError("boundary", f"is not a simple polygon: {explain_validity(field)}")
    if field.area <= 0:
        raise PathError("boundary", "encloses no area")
    area = field.buffer(-headland, join_style="mitre") if headland > 0 else field
    if area.is_empty or area.geom_type != "Polygon":
        raise PathError("headland", f"{headland:g} m leaves no single area to drive inside "
                                    "the boundary: make it narrower")
    if angle is None:
        angle = _long_side(area)
    turn_radius = min(spacing / 2.0, room) if room > 0 else 0.0
    if turn_radius <= 0:
        raise PathError("headland", "no room to turn beyond the swaths: give a headland "
                                    "(a survey: a turnaround distance)")

    # In a frame turned by -angle the swaths run along +x (north); shapely turns
    # counter-clockwise in its (x, y) plane, which is (north, east) here.
    flat = affinity.rotate(area, -angle, origin=(0, 0), use_radians=True)
    phase = (None if through is None else
             affinity.rotate(Point(through), -angle, origin=(0, 0), use_radians=True).y)
    segments, slivers = _segments(flat, spacing, phase)

    points, swaths = _drive(segments, angle, turn_radius, start)
    strips = [LineString([p, q]).buffer(spacing / 2.0, cap_style="flat") for p, q in swaths]
    covered = unary_union(strips).intersection(area).area / area.area
    note = (f"{len(swaths)} swaths at {spacing:g} m heading {math.degrees(angle) % 180:.1f} deg, "
            f"turns of {turn_radius:.2f} m, {100 * covered:.1f} % of the "
            f"{area.area:.0f} m^2 swath area covered at the spacing"
            + (f" ({slivers} corner slivers shorter than the spacing left out)" if slivers
               else ""))
    allowed = area.buffer(room + 1e-3, join_style="mitre")
    cover = FieldCover(tuple(swaths), spacing, tuple(area.exterior.coords),
                       tuple(allowed.exterior.coords))
    driven = list(lead_in) + points + list(lead_out)
    joined = [p for i, p in enumerate(driven) if i == 0 or math.dist(p, driven[i - 1]) > 0.01]
    whole = Route(tuple(joined), limits, corner_radius=turn_radius, kind=kind, note=note,
                  cover=cover)
    # the room is checked on the field's own part (a lead-in from home may come from anywhere)
    route = (whole if not (lead_in or lead_out) else
             Route(tuple(points), limits, corner_radius=turn_radius))
    path = LineString(route.outline())
    if not allowed.contains(path):
        out = path.difference(allowed).length
        raise PathError("headland", f"the turns leave the room given for them by {out:.2f} m "
                                    "of path: widen the headland (a survey: the turnaround)")
    return FieldPlan(whole, tuple(swaths), angle, spacing, turn_radius, covered)


def _segments(flat, spacing: float, phase: float | None
              ) -> tuple[list[tuple[float, float, float]], int]:
    """The swaths across ``flat`` (the swath area turned so they run along x) as (x from,
    x to, y), and how many corner slivers were left out; lines centred, or through y =
    ``phase``."""
    from shapely.geometry import LineString
    minx, miny, maxx, maxy = flat.bounds
    width = maxy - miny
    if phase is None:
        count = max(1, math.ceil(width / spacing - 1e-9))
        first = miny + 0.5 * (width - (count - 1) * spacing)
    else:
        first = phase + math.ceil((miny - phase) / spacing - 1e-9) * spacing
        count = max(1, math.floor((maxy - first) / spacing + 1e-9) + 1)
    if count > MAX_SWATHS:
        raise PathError("spacing", f"{spacing:g} m gives {count} swaths across "
                                   f"{width:.0f} m, more than {MAX_SWATHS}")
    segments = []
    slivers = 0
    for k in range(count):
        y = first + k * spacing
        cut = LineString([(minx - 1.0, y), (maxx + 1.0, y)]).intersection(flat)
        if cut.is_empty or cut.length < EDGE:
            continue
        if cut.geom_type != "LineString":
            raise PathError("boundary", f"swath {k + 1} crosses the field in "
                                        f"{len(getattr(cut, 'geoms', ()))} parts (a concave "
                                        "field): split it into convex fields")
        (x0, _), (x1, _) = cut.coords[0], cut.coords[-1]
        if abs(x1 - x0) < spacing:
            slivers += 1        # a corner's sliver, shorter than the tool is wide: a turn
            continue            # for less than its own area (QGroundControl drops them too)
        segments.append((min(x0, x1), max(x0, x1), y))
    if not segments:
        raise PathError("spacing", "no swath fits inside the field")
    return segments, slivers


def _drive(segments: list[tuple[float, float, float]], angle: float, turn_radius: float,
           start: tuple[float, float] | None
           ) -> tuple[list[tuple[float, float]],
                      list[tuple[tuple[float, float], tuple[float, float]]]]:
    """The route's points (each swath extended by the turn radius) and the swaths as driven,
    turned back to (north, east): in turn, alternating, from the entry corner nearest
    ``start`` (first or last swath, either way along it)."""
    c, s = math.cos(angle), math.sin(angle)

    def back(x: float, y: float) -> tuple[float, float]:
        return (c * x - s * y, s * x + c * y)

    flip = False
    if start is not None:
        def entry(order: list, flip: bool) -> float:
            x0, x1, y = order[0]
            ex, ey = back((x1 + turn_radius) if flip else (x0 - turn_radius), y)
            return math.hypot(ex - start[0], ey - start[1])
        options = [(entry(o, f), i, o, f) for i, (o, f) in enumerate(
            (o, f) for o in (segments, segments[::-1]) for f in (False, True))]
        _, _, segments, flip = min(options)
    points: list[tuple[float, float]] = []
    swaths = []
    for k, (x0, x1, y) in enumerate(segments):
        a, b = (x0, x1) if (k % 2 == 0) != flip else (x1, x0)
        ext = turn_radius if b > a else -turn_radius
        swaths.append((back(a, y), back(b, y)))
        points += [back(a - ext, y), back(b + ext, y)]
    return points, swaths


def _long_side(area) -> float:
    """The heading of the longest side of ``area``'s minimum rotated rectangle."""
    corners = list(area.minimum_rotated_rectangle.exterior.coords)
    best, heading = -1.0, 0.0
    for (x0, y0), (x1, y1) in zip(corners, corners[1:], strict=False):
        length = math.hypot(x1 - x0, y1 - y0)
        if length > best + 1e-9:
            best, heading = length, math.atan2(y1 - y0, x1 - x0)
    return heading % math.pi

