"""Mission files: the reference trajectory a user asks for, checked before anything moves.

Each kind of ``[trajectory]`` is built in :mod:`companion.mission.trajectory_table`.

A mission is a TOML file (or a QGroundControl ``.plan`` / ``QGC WPL 110`` ``.waypoints`` file,
imported by :mod:`companion.mission.plan_import`)::

    name = "circle"
    description = "5 m circle at 1.5 m/s"
    frame = "start"          # "start" (default): relative to the start pose, x ahead, y right;
                             # "local": LOCAL_NED (EKF origin); "geodetic": metres from `origin`
    # origin = [lat, lon]    # only with frame = "geodetic"
    laps = 3                 # or duration = 60 (s); default: the motion's end, or one lap
    rate_hz = 40             # optional loop rate
    # gains_file = "tuned.toml"   (or the tables [gains.filter] / [gains.pzc], as companion.sim.gains)

    [trajectory]
    kind = "circle"          # ellipse | circle | figure8 | line | polyline | waypoints | plan
    center = [0.0, 5.0]
    radius = 5.0
    speed = 1.5

    [limits]                 # optional: the trajectory must stay within them
    max_speed = 2.0
    max_yaw_rate = 1.0

    [vehicle]                # optional, for simulation: companion.sim.plant.RoverParams fields
    d_cen = 0.0
    w_c = 20.0
    file = "rover.toml"      # optional: the identified vehicle; the keys above override it

A ``[vehicle] file`` is named here, not read: the command flying the mission loads it once
(:func:`companion.app.vehicle.for_mission`) and applies the keys over it (``Mission.vehicle``
is None until then).

Every problem is one :class:`~companion.errors.UserError` line naming the file, the key path and
the bad value: unknown keys, missing or mistyped fields, non-finite numbers, non-increasing
waypoint times, a trajectory exceeding the limits, a file that is not there.

The paper's ellipse starts at (6, 2) with the rover at rest at the origin facing north: in frame
"start" that is where it starts for a rover anywhere, pointing anywhere.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any

from ..core.filter import FilterGains
from ..core.limits import Limits
from ..core.pzc import PZCGains
from ..core.trajectory import Ellipse, Trajectory
from ..errors import UserError
from ..sim import gains as _gains
from ..sim.plant import RoverParams
from . import paths
from .coverage import FieldCover
from .polyline import Polyline
from .profile import MotionProfile, limit_problem, measure
from .schema import Table, short
from .spline import TimedWaypoints
from .trajectory_table import MAX_DURATION, build, file_key, read_plan, waypoint_path

FRAMES = ("start", "local", "geodetic")
SUFFIXES = (".toml", ".plan", ".waypoints")


@dataclass(frozen=True)
class Mission:
    name: str
    description: str
    trajectory: Trajectory            # sample(t) -> Reference (floats for float t), .duration
    duration: float                   # seconds of tracking (from `duration` or `laps` x period)
    rate_hz: float | None             # loop rate wanted, None = the companion's default (40 Hz)
    filter_gains: FilterGains | None
    pzc_gains: PZCGains | None
    limits: Limits | None
    vehicle: RoverParams | None       # for simulation (d_cen, w_c); None with a [vehicle]
                                      # file until the command loads it (with_vehicle_file)
    frame: str                        # "start" (relative to the start pose) or "local"
    source: str                       # the file it came from
    kind: str = ""                    # trajectory kind, e.g. "circle"
    period: float | None = None       # s per lap for periodic trajectories
    profile: MotionProfile | None = None   # length and peaks over the mission
    warnings: tuple[str, ...] = ()    # one line per imported item that is not followed
    vehicle_file: str | None = None   # [vehicle] file: the identified vehicle (companion identify)
    vehicle_keys: tuple[tuple[str, float], ...] = ()   # [vehicle]'s own keys (over the file's)
    # Placed by latitude / longitude (TOML frame "geodetic", kind "plan", .plan, .waypoints):
    # `datum` is the (lat, lon) of the trajectory's local (0, 0), the EKF origin it was loaded
    # for (else the plan's home or the TOML's own origin); `placer` reloads the same mission
    # around another origin with ArduPilot's exact maths (`at_origin`).
    geodetic: bool = False
    datum: tuple[float, float] | None = None
    placer: Callable[..., Mission] | None = field(default=None, compare=False, repr=False)

    def with_vehicle_file(self, params: RoverParams) -> Mission:
        """The mission with its ``[vehicle] file``'s model (loaded by the command) under its
        own ``[vehicle]`` keys."""
        return replace(self, vehicle=params.with_(**dict(self.vehicle_keys)))

    def at_origin(self, origin: tuple[float, float]) -> Mission:
        """The same mission placed around the EKF origin ``origin`` = (lat, lon) (a local or
        start-frame mission is returned as it is). Files are read again: a file changed or gone
        since is a UserError, still before anything moves."""
        if not self.geodetic or self.placer is None:
            return self
        placed = self.placer(origin=origin)
        # a duration set since loading (companion demo --duration) is kept
        return placed if placed.duration == self.duration else replace(placed,
                                                                         duration=self.duration)

    def anchored(self, x0: float, y0: float, yaw0: float) -> Trajectory:
        """The trajectory in the vehicle's local NED frame for a start pose (identity for frame
        'local'; for 'start': rotate by yaw0 and translate by (x0, y0))."""
        if self.frame == "local" or (x0, y0, yaw0) == (0.0, 0.0, 0.0):
            return self.trajectory
        return paths.Placed(self.trajectory, float(x0), float(y0), float(yaw0))

    def field_cover(self) -> FieldCover | None:
        """What a field's route is meant to cover, in the frame the mission is flown in (moved
        as its trajectory is; a "start" frame's anchoring is the run's), or None."""
        traj = self.trajectory
        cover = getattr(_unplaced(traj), "cover", None)
        if cover is not None and isinstance(traj, paths.Placed):
            cover = cover.placed(traj.x, traj.y, traj.yaw)
        return cover

    def summary(self) -> str:
        """One line: kind, length, duration, peak speed and turn rate against the limits."""
        p = self.profile
        lim = self.limits or Limits()

        def against(value: float, limit: float, unit: str) -> str:
            text = f"{value:.2f} {unit}"
            return text + (f" (limit {limit:g})" if math.isfinite(limit) else " (no limit)")

        parts = [self.kind, f"frame {self.frame}"]
        if p is not None:
            parts += [f"{p.length:.1f} m", f"{self.duration:.1f} s",
                      "peak speed " + against(p.peak_speed, lim.max_speed, "m/s"),
                      "turn rate " + against(p.peak_turn_rate, lim.max_yaw_rate, "rad/s")]
        else:
            parts.append(f"{self.duration:.1f} s")
        note = getattr(_unplaced(self.trajectory), "note", "")
        return ", ".join(parts) + (f"; {note}" if note else "")


# --------------------------------------------------------------------------- entry points


def paper_ellipse(f_r: float = 0.12, duration: float = 60.0) -> Mission:
    """Section 5's reference p_ref = [6 cos - sin, 2 cos + 3 sin](2 pi f_r t): the demo's default."""
    trajectory = Ellipse.paper(f_r, duration)
    return Mission(
        name=f"paper ellipse {f_r:g} Hz",
        description="Lee et al. (2024), Section 5: p_ref = [6 cos - sin, 2 cos + 3 sin](2 pi f_r t)",
        trajectory=trajectory, duration=float(duration), rate_hz=None, filter_gains=None,
        pzc_gains=None, limits=None, vehicle=None, frame="start", source="<paper ellipse>",
        kind="ellipse", period=1.0 / f_r,
        profile=measure(trajectory, duration, period=1.0 / f_r))


def load(path: str | Path, *, origin: tuple[float, float] | None = None,
         speed: float | None = None) -> Mission:
    """Read and check a mission file: ``.toml``, ``.plan`` or ``.waypoints`` (by suffix).

    ``origin`` = (lat, lon) of the vehicle's EKF origin, for geodetic files (None: the plan's
    home, or the TOML's own origin). ``speed`` overrides an imported plan's cruise speed.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise UserError(f"{path}: unknown mission file type {suffix or '(no suffix)'!r}: "
                        "expected .toml, .plan or .waypoints")
    if suffix == ".toml":
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise UserError(f"{path}: no such file") from None
        except IsADirectoryError:
            raise UserError(f"{path}: is a directory, not a mission file") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise UserError(f"{path}: cannot read: {exc}") from None
        return loads(text, str(path), origin=origin, base_dir=path.parent)
    mission = _from_plan(path, origin=origin, speed=speed, corner_radius=None)
    return replace(mission, placer=partial(load, path, speed=speed))


def loads(text: str, source: str = "<mission>", *, origin: tuple[float, float] | None = None,
          base_dir: str | Path | None = None) -> Mission:
    """Check a TOML mission given as text (e.g. sent by a remote ``load-mission``).

    Relative file names inside (``gains_file``, a plan's ``file``) are taken from ``base_dir``
    (default: the current directory).
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{source}: not valid TOML: {exc}") from None
    mission = _from_table(Table(data, source), Path(base_dir) if base_dir else Path("."), origin)
    if mission.geodetic:
        mission = replace(mission, placer=partial(loads, text, source, base_dir=base_dir))
    return mission


# --------------------------------------------------------------------------- TOML missions


def _from_table(top: Table, base: Path, origin: tuple[float, float] | None) -> Mission:
    src = top.source
    name = top.string("name", default=Path(src).stem if src != "<mission>" else "mission")
    description = top.string("description", default="")
    frame = top.string("frame", default="start", choices=FRAMES)
    geo_origin = None
    if frame == "geodetic":
        geo_origin = _latlon(top, "origin", required=True)
    elif top.has("origin"):
        raise top.error("origin", 'only belongs with frame = "geodetic"')
    rate_hz = top.number("rate_hz", positive=True, maximum=1000.0)
    duration = top.number("duration", positive=True, maximum=MAX_DURATION)
    laps = top.number("laps", positive=True, maximum=1e6)
    if duration is not None and laps is not None:
        raise top.error("laps", f"give duration or laps, not both (duration = {duration:g})")
    filter_gains, pzc_gains = _read_gains(top, base)
    limits = _read_limits(top.table("limits"))
    vehicle, vehicle_file, vehicle_keys = _read_vehicle(top.table("vehicle"), base)
    spec = top.table("trajectory", required=True)
    traj, warnings, datum = build(spec, base, laps, origin,
                                  start=(0.0, 0.0) if frame == "start" else None)
    top.done()

    kind = spec.data["kind"]
    geodetic = kind == "plan" or frame == "geodetic"
    if kind == "plan":
        if frame not in ("start", "local") or (top.has("frame") and frame != "local"):
            raise top.error("frame", f'a plan is placed by lat/lon: leave frame out or use '
                                     f'"local", not {short(frame)}')
        frame = "local"
    if frame == "geodetic":
        from . import geo
        assert geo_origin is not None   # read with required=True above
        shift = geo.ne_from_latlon(*geo_origin, origin) if origin is not None else (0.0, 0.0)
        datum = origin if origin is not None else geo_origin
        frame = "local"
    else:
        shift = None

    period = _period(traj)
    duration = _duration(top, traj, period, duration, laps)
    traj = replace(traj, duration=duration)
    profile = _profile(top, traj, duration, period, limits)
    if shift is not None and shift != (0.0, 0.0):
        traj = paths.Placed(traj, shift[0], shift[1], 0.0)
    return Mission(name=name, description=description, trajectory=traj, duration=duration,
                   rate_hz=rate_hz, filter_gains=filter_gains, pzc_gains=pzc_gains,
                   limits=limits, vehicle=vehicle, frame=frame, source=src,
                   kind=_kind_name(traj), period=period, profile=profile,
                   warnings=tuple(warnings), vehicle_file=vehicle_file,
                   vehicle_keys=vehicle_keys, geodetic=geodetic, datum=datum)


def _latlon(table: Table, key: str, required: bool = False) -> tuple[float, float] | None:
    from . import geo
    value = table.point(key, required=required)
    if value is None:
        return None
    problem = geo.check_latlon(*value)
    if problem:
        raise table.error(key, problem)
    return value


def _read_gains(top: Table, base: Path) -> tuple[FilterGains | None, PZCGains | None]:
    gains_file = top.string("gains_file")
    table = top.table("gains")
    if gains_file is not None and table is not None:
        raise top.error("gains_file", "give gains_file or a [gains] table, not both")
    if gains_file is not None:
        path = file_key(top, "gains_file", gains_file, base)
        try:
            tuned = _gains.load(path)
        except UserError as err:   # name the mission file and key too, still on one line
            raise top.error("gains_file", str(err)) from None
        return tuned.filter, tuned.pzc
    if table is None:
        return None, None
    data = dict(table.data)
    # companion.sim.gains.parse wants both sections; a mission may give either one alone, so a
    # missing one gets placeholder values that are then dropped.
    have_filter, have_pzc = "filter" in data, "pzc" in data
    data.setdefault("filter", {"k_df": 1.0, "lambda_f": 1.0})
    data.setdefault("pzc", {"k_dc": 1.0, "lambda_c": 1.0})
    tuned = _gains.parse(data, f"{top.source}: gains")
    return (tuned.filter if have_filter else None), (tuned.pzc if have_pzc else None)


def _read_limits(table: Table | None) -> Limits | None:
    if table is None:
        return None
    limits = Limits(max_speed=table.number("max_speed", math.inf, positive=True),
                    max_yaw_rate=table.number("max_yaw_rate", math.inf, positive=True))
    table.done()
    return limits


def _read_vehicle(table: Table | None, base: Path
                  ) -> tuple[RoverParams | None, str | None, tuple[tuple[str, float], ...]]:
    """``[vehicle]``: (the model of its keys, None when a vehicle file is named (the command
    loads it: ``Mission.with_vehicle_file``); the file's path; the keys given). The file
    (``file = "rover.toml"``, from ``companion identify``) is named relative to the mission."""
    if table is None:
        return None, None, ()
    path = None
    name = table.string("file")
    if name is not None:
        path = file_key(table, "file", name, base)
        if not path.is_file():
            raise table.error("file", f"{path}: no such vehicle file")
    keys: dict[str, dict[str, Any]] = {"d_cen": dict(minimum=0.0, maximum=100.0), "w_c": dict(positive=True, maximum=1e4),
            "w_c_yaw": dict(positive=True, maximum=1e4), "max_speed": dict(positive=True),
            "max_yaw_rate": dict(positive=True), "max_accel": dict(positive=True)}
    given = {k: table.number(k, None, **kw) for k, kw in keys.items()}
    table.done()
    own = tuple((k, v) for k, v in given.items() if v is not None)
    if path is not None:
        return None, str(path), own
    return RoverParams().with_(**dict(own)), None, own


def _period(traj) -> float | None:
    if isinstance(traj, Ellipse):
        return 1.0 / float(traj.f_r)
    return getattr(traj, "period", None)


def _unplaced(traj):
    """The trajectory inside a :class:`paths.Placed` (itself when it is not placed)."""
    return getattr(traj, "inner", traj)


def _kind_name(traj) -> str:
    inner = _unplaced(traj)
    return "ellipse" if isinstance(inner, Ellipse) else inner.kind


def _duration(top: Table, traj, period: float | None, duration: float | None,
              laps: float | None) -> float:
    start = 0.0
    if isinstance(traj, TimedWaypoints) and traj.closed:
        start = traj.waypoints[0][0]           # the laps begin at the first waypoint's time
    if laps is not None:
        if isinstance(traj, Polyline) and traj.closed:
            end = traj.motion_end              # built for these laps, ramps included
            result = math.inf if end is None else end
        elif period is None:
            raise top.error("laps", f"needs a periodic trajectory; this {_kind_name(traj)} is "
                                    "open: give duration instead")
        else:
            result = start + laps * period
    elif duration is not None:
        result = duration
    else:
        end = getattr(traj, "motion_end", None)
        result = end if end is not None else start + (period or 0.0)
    if not (math.isfinite(result) and 0.01 <= result <= MAX_DURATION):
        raise top.error("laps" if laps is not None else "duration",
                        f"the mission would last {result:.6g} s: it must be 0.01 s to "
                        f"{MAX_DURATION:g} s")
    return float(result)


def _profile(top: Table, traj, duration: float, period: float | None,
             limits: Limits | None) -> MotionProfile:
    if isinstance(traj, TimedWaypoints) and traj.waypoints[0][0] > 0:
        period = None   # the laps start late: sample the whole mission, not [0, period]
    try:
        profile = measure(traj, duration, period=period, motion_end=getattr(traj, "motion_end", None))
    except (ArithmeticError, ValueError) as exc:
        raise top.error("trajectory", str(exc)) from None
    if limits is not None:
        problem = limit_problem(profile, limits, getattr(traj, "where", None))
        if problem is not None:
            key, message = problem
            advice = ("allow more time between them" if isinstance(traj, TimedWaypoints)
                      else "slow it down")
            raise top.error("trajectory", f"{message}: {advice} or raise limits.{key}")
    return profile


def from_local_points(name: str, points, speed: float, source: str,
                      description: str = "") -> Mission:
    """A mission along ``points`` (local north, east metres around the EKF origin) at
    ``speed``, as a .plan's waypoints are flown (a hand-over segment: companion.live.handover)."""
    traj, duration, profile = waypoint_path(points, speed, None, source)
    return Mission(name=name, description=description, trajectory=traj, duration=duration,
                   rate_hz=None, filter_gains=None, pzc_gains=None, limits=None, vehicle=None,
                   frame="local", source=source, kind="plan", period=None, profile=profile)


def _from_plan(path: Path, *, origin: tuple[float, float] | None, speed: float | None,
               corner_radius: float | None) -> Mission:
    plan = read_plan(path, origin=origin, speed=speed, corner_radius=corner_radius)
    return Mission(
        name=path.stem, description=plan.description, trajectory=plan.trajectory,
        duration=plan.duration, rate_hz=None, filter_gains=None, pzc_gains=None, limits=None,
        vehicle=None, frame="local", source=str(path), kind="plan", period=None,
        profile=plan.profile, warnings=plan.warnings, geodetic=True, datum=plan.datum)
