"""A mission file's ``[trajectory]`` table: each kind (ellipse, circle, figure-8, line,
polyline, timed waypoints, an imported plan) built from its keys and checked, every problem one
line naming the key; and the path a plan's waypoints are flown along.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..core.trajectory import Ellipse, Trajectory
from ..errors import UserError
from . import paths
from .polyline import Polyline
from .profile import measure
from .schema import Table, check_rows, short
from .spline import TimedWaypoints

KINDS = ("ellipse", "circle", "figure8", "line", "polyline", "waypoints", "plan", "field")
MAX_DURATION = 86400.0     # s: one day of tracking is plenty; bounds the checks' cost
MAX_DISTANCE = 1e6         # m
MAX_SPEED = 100.0          # m/s
MIN_LENGTH = 1e-3          # m
PLAN_CORNER_RADIUS = 2.0   # m: ArduPilot Rover's WP_RADIUS default, shrunk to fit short legs
DEFAULT_ACCEL = 0.5        # m/s^2, peak along-path acceleration of line / polyline / plans


def build(spec: Table, base: Path, laps: float | None, origin: tuple[float, float] | None,
          start: tuple[float, float] | None = None) -> tuple[Any, tuple[str, ...], Any]:
    """(the trajectory (a dataclass: Ellipse, a path), warnings, the datum of one placed by lat / lon) of a ``[trajectory]``
    table; every problem a one-line error naming the key. ``start``: where the rover is known
    to start (frame "start": the frame's origin), for a field's entry corner."""
    kind = spec.string("kind", required=True, choices=KINDS)
    speed: dict[str, Any] = {"positive": True, "maximum": MAX_SPEED}
    warnings: tuple[str, ...] = ()
    traj: Trajectory
    points: tuple[tuple[float, float], ...]
    datum = None
    try:
        if kind == "ellipse":
            traj = Ellipse(
                f_r=spec.number("f_r", required=True, positive=True, maximum=100.0),
                **{k: spec.number(k, getattr(Ellipse, k), maximum=MAX_DISTANCE,
                                  minimum=-MAX_DISTANCE) for k in ("ax", "bx", "ay", "by", "cx", "cy")})
        elif kind == "circle":
            radius = spec.number("radius", required=True, minimum=MIN_LENGTH, maximum=MAX_DISTANCE)
            v = _speed_or_period(spec, radius)
            traj = paths.Circle(
                center=_point(spec, "center", (0.0, 0.0)), radius=radius, speed=v,
                clockwise=spec.string("direction", "cw", choices=("cw", "ccw")) == "cw",
                start_bearing=math.radians(spec.number("start_bearing_deg", 0.0)))
        elif kind == "figure8":
            traj = paths.FigureEight(
                center=_point(spec, "center", (0.0, 0.0)),
                length=spec.number("length", required=True, minimum=MIN_LENGTH, maximum=MAX_DISTANCE),
                width=spec.number("width", required=True, minimum=MIN_LENGTH, maximum=MAX_DISTANCE),
                period=spec.number("period", required=True, minimum=0.01, maximum=MAX_DURATION),
                heading=math.radians(spec.number("heading_deg", 0.0)))
        elif kind in ("line", "polyline"):
            if kind == "line":
                points = (_point(spec, "start", (0.0, 0.0)), _point(spec, "end", required=True))
                closed = False
            else:
                rows = check_rows(spec.require("points"), 2, spec.source, spec.key("points"),
                                  "[north, east]", 2, 1000)
                points = tuple(_bounded(spec, f"points[{i}]", p) for i, p in enumerate(rows))
                closed = spec.boolean("closed", False)
            traj = Polyline(
                points=points, speed=spec.number("speed", required=True, **speed),
                corner_radius=(spec.number("corner_radius", 1.0, minimum=MIN_LENGTH,
                                           maximum=MAX_DISTANCE) if kind == "polyline" else 1.0),
                accel=spec.number("accel", DEFAULT_ACCEL, positive=True, maximum=100.0),
                closed=closed, laps=laps if closed else None)
        elif kind == "waypoints":
            rows = check_rows(spec.require("waypoints"), 3, spec.source, spec.key("waypoints"),
                              "[t, north, east]", 2, TimedWaypoints.MAX_POINTS)
            for i, row in enumerate(rows):
                if not 0.0 <= row[0] <= MAX_DURATION:
                    raise spec.error(f"waypoints[{i}][0]", f"time must be in [0, {MAX_DURATION:g}] "
                                                           f"s, not {row[0]!r}")
                _bounded(spec, f"waypoints[{i}]", row[1:])
            traj = TimedWaypoints(tuple((t, n, e) for t, n, e in rows), closed=spec.boolean("closed", False))
        elif kind == "field":
            traj = _field(spec, start)
        else:  # plan
            name = spec.string("file", required=True)
            path = file_key(spec, "file", name, base)
            if path.suffix.lower() not in (".plan", ".waypoints"):
                raise spec.error("file", f"must be a .plan or .waypoints file, not {short(name)}")
            plan_speed = spec.number("speed", None, **speed)
            corner = spec.number("corner_radius", None, minimum=MIN_LENGTH, maximum=MAX_DISTANCE)
            try:
                imported = read_plan(path, origin=origin, speed=plan_speed,
                                     corner_radius=corner)
            except UserError as err:   # name the mission file and key, then the plan's problem
                raise spec.error("file", str(err)) from None
            traj, warnings, datum = imported.trajectory, imported.warnings, imported.datum
    except paths.PathError as exc:
        raise spec.error(exc.key, str(exc)) from None
    spec.done()
    return traj, warnings, datum


def _field(spec: Table, start: tuple[float, float] | None) -> Trajectory:
    """``kind = "field"``: a boundary covered by swaths (companion.mission.field)."""
    from . import field
    rows = check_rows(spec.require("boundary"), 2, spec.source, spec.key("boundary"),
                      "[north, east]", 3, 10000)
    boundary = [_bounded(spec, f"boundary[{i}]", p) for i, p in enumerate(rows)]
    angle = spec.number("angle_deg", None, minimum=-360.0, maximum=360.0)
    plan = field.plan(
        boundary, spacing=spec.number("spacing", required=True, minimum=0.01, maximum=1000.0),
        headland=spec.number("headland", required=True, minimum=0.0, maximum=1000.0),
        angle=None if angle is None else math.radians(angle), limits=route_limits(spec),
        start=start)
    return plan.route


def route_limits(spec: Table):
    """A route's time law from a table's ``speed``, ``turn_rate``, ``lateral_accel``, ``accel``."""
    from .route import RouteLimits
    return RouteLimits(
        speed=spec.number("speed", required=True, positive=True, maximum=MAX_SPEED),
        turn_rate=spec.number("turn_rate", 0.5, positive=True, maximum=100.0),
        lateral_accel=spec.number("lateral_accel", 0.5, positive=True, maximum=100.0),
        accel=spec.number("accel", DEFAULT_ACCEL, positive=True, maximum=100.0))


def file_key(table: Table, key: str, name: str, base: Path) -> Path:
    """A file named in the mission, relative to the mission file's directory."""
    if not name or "\x00" in name:
        raise table.error(key, f"is not a file name: {short(name)}")
    path = Path(name)
    return path if path.is_absolute() else base / path


def _point(spec: Table, key: str, default=None, required: bool = False):
    value = spec.point(key, default, required=required)
    return value if value is None else _bounded(spec, key, value)


def _bounded(spec: Table, key: str, point) -> tuple[float, float]:
    if any(abs(v) > MAX_DISTANCE for v in point):
        raise spec.error(key, f"{tuple(point)} is more than {MAX_DISTANCE:g} m away")
    return (float(point[0]), float(point[1]))


def _speed_or_period(spec: Table, radius: float) -> float:
    if spec.has("speed") and spec.has("period"):
        raise spec.error("period", "give speed or period, not both")
    if spec.has("period"):
        period = spec.number("period", required=True, minimum=0.01, maximum=MAX_DURATION)
        return 2.0 * math.pi * radius / period
    return spec.number("speed", required=True, positive=True, maximum=MAX_SPEED)


def waypoint_path(points, speed: float, corner_radius: float | None, source: str):
    """(trajectory, duration, profile) of a path through ``points`` (local north, east) at
    ``speed``: corners rounded as a .plan's, raised-cosine ramps at both ends."""
    try:
        traj = Polyline(points, speed=speed, corner_radius=corner_radius or PLAN_CORNER_RADIUS,
                        accel=DEFAULT_ACCEL, shrink_corners=True)
    except paths.PathError as exc:
        raise UserError(f"{source}: {exc}") from None
    return _to_its_end(traj, source)


def _to_its_end(traj, source: str):
    """(trajectory, duration, profile) of an open path (a plan's, a survey's) flown until it
    comes to rest at its end."""
    duration = traj.motion_end
    assert duration is not None   # an open path comes to a stop
    traj = replace(traj, duration=duration)
    try:
        profile = measure(traj, duration, motion_end=duration)
    except (ArithmeticError, ValueError) as exc:
        raise UserError(f"{source}: {exc}") from None
    return traj, duration, profile


@dataclass(frozen=True)
class PlanPath:
    """A .plan or .waypoints file as the path flown along its waypoints."""

    trajectory: Any
    duration: float
    profile: Any                       # mission.profile.MotionProfile
    warnings: tuple[str, ...]
    datum: tuple[float, float]         # the (lat, lon) its local (0, 0) is
    description: str


def read_plan(path: Path, *, origin: tuple[float, float] | None, speed: float | None,
              corner_radius: float | None) -> PlanPath:
    """A plan flown at ``speed`` (else the file's, else the default), placed around
    ``origin`` (else its home)."""
    from . import plan_import
    plan = plan_import.read(path, origin=origin)
    warnings = list(plan.warnings)
    if speed is None:
        speed = plan.speed
        if speed is None:
            speed = plan_import.DEFAULT_SPEED
            warnings.append(f"{path}: the file gives no speed: using {speed:g} m/s")
    where = "home" if plan.home is not None and plan.origin == plan.home else "the EKF origin"
    if plan.survey is not None:
        return _survey_path(path, plan, speed, warnings, where)
    traj, duration, profile = waypoint_path(plan.points, speed, corner_radius, str(path))
    return PlanPath(traj, duration, profile, tuple(warnings), plan.origin,
                    f"imported from {path.name}: {plan.waypoint_count} waypoints at {speed:g} "
                    f"m/s, relative to {where} {plan.origin[0]:.7f}, {plan.origin[1]:.7f}")


def _survey_path(path: Path, plan, speed: float, warnings: list[str], where: str) -> PlanPath:
    """A plan's QGroundControl Survey as a field (companion.mission.survey), entered where
    QGroundControl's first transect begins, at the straight ``speed``."""
    from . import field, geo, survey
    from .route import RouteLimits
    sv = plan.survey

    def local(p: tuple[float, float]) -> tuple[float, float]:
        return geo.ne_from_latlon(p[0], p[1], plan.origin)

    transects = [(local(a), local(b)) for a, b in sv.transects]
    try:
        planned = field.plan([local(p) for p in sv.polygon], spacing=sv.spacing,
                             limits=RouteLimits(speed=speed), angle=math.radians(sv.angle_deg),
                             headland=0.0, turn_room=sv.turnaround,
                             start=(plan.points[plan.survey_at - 1] if plan.survey_at else
                                    transects[0][0] if transects else None), kind="survey",
                             lead_in=plan.points[:plan.survey_at],
                             lead_out=plan.points[plan.survey_at:],
                             through=transects[0][0] if transects else None)
    except paths.PathError as exc:
        raise UserError(f"{path}: {sv.where}: {exc.key}: {exc}") from None
    traj, duration, profile = _to_its_end(planned.route, str(path))
    said, agree = survey.compare(planned.swaths, transects, sv.spacing)
    if not agree:
        warnings.append(f"{path}: {sv.where}: {said}")
    return PlanPath(traj, duration, profile, tuple(warnings), plan.origin,
                    f"imported from {path.name}: a QGroundControl survey flown as a field at "
                    f"{speed:g} m/s, relative to {where} {plan.origin[0]:.7f}, "
                    f"{plan.origin[1]:.7f}; {said}")
