"""Reference trajectories a mission file can ask for, beside the paper's :class:`Ellipse`.

Every kind gives position, velocity and acceleration analytically for any time ``t`` (seconds
after tracking starts) through ``sample(t) -> Reference``, on plain floats, as the live loop
needs. All are frozen dataclasses with a ``duration`` field (seconds of tracking, or None) and:

* ``period``: seconds per lap for periodic kinds, else None;
* ``motion_end``: the time after which an open path stands still at its end, else None.

Kinds (coordinates are (north, east) metres, headings radians from north towards east):

* :class:`Circle`: constant speed round a centre, clockwise or counter-clockwise seen from above.
* :class:`FigureEight`: the 1:2 Lissajous figure x = L/2 sin(wt), y = W/2 sin(2wt), rotated.
* :class:`Polyline` (and a straight line, a polyline of two points): straight sides joined by
  circular arcs of radius ``corner_radius`` tangent to both sides (fillets), so the velocity is
  continuous and the turn rate finite (speed / radius); the acceleration jumps by speed^2/radius
  where an arc begins or ends. The speed along the path rises from rest to ``speed`` and falls to
  rest at the end with a raised-cosine profile whose peak acceleration is ``accel``, so velocity
  and along-path acceleration are continuous.
* :class:`TimedWaypoints`: a quintic spline through (t_i, x_i, y_i), continuous up to the fourth
  derivative; an open spline starts and ends at rest with zero acceleration (so the reference is
  C2 also where it joins the standstill before and after), a closed one is periodic.
* :class:`Placed`: any trajectory turned by a yaw and shifted (a mission given relative to the
  start pose, anchored at the vehicle's actual pose).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .signals import Reference

_TWO_PI = 2.0 * math.pi


def _wrap(angle: float) -> float:
    return (angle + math.pi) % _TWO_PI - math.pi


class PathError(ValueError):
    """A path that cannot be built as asked; ``key`` names the offending parameter."""

    def __init__(self, key: str, message: str):
        super().__init__(message)
        self.key = key


# --------------------------------------------------------------------------- periodic shapes


@dataclass(frozen=True)
class Circle:
    """x = cx + r cos(s w t + b0), y = cy + r sin(s w t + b0), w = speed / r.

    ``s`` is +1 for clockwise seen from above (north towards east), -1 for counter-clockwise;
    ``start_bearing`` b0 is the bearing (radians from north towards east) of the start point seen
    from the centre.
    """

    center: tuple[float, float]
    radius: float
    speed: float
    clockwise: bool = True
    start_bearing: float = 0.0
    duration: float | None = None

    kind = "circle"
    motion_end = None

    @property
    def period(self) -> float:
        return _TWO_PI * self.radius / self.speed

    def peaks(self) -> tuple[float, float]:
        """(peak speed, peak turn rate), exactly."""
        return self.speed, self.speed / self.radius

    def sample(self, t: float) -> Reference:
        s = 1.0 if self.clockwise else -1.0
        w = s * self.speed / self.radius
        ang = w * t + self.start_bearing
        c, sn = math.cos(ang), math.sin(ang)
        r = self.radius
        return Reference(self.center[0] + r * c, self.center[1] + r * sn,
                         -r * w * sn, r * w * c, -r * w * w * c, -r * w * w * sn)


@dataclass(frozen=True)
class FigureEight:
    """A figure-eight: in its own axes a = L/2 sin(wt) along, b = W/2 sin(2wt) across, w = 2 pi / T.

    ``heading`` turns the long axis from north towards east; the figure is centred on ``center``
    and starts there, crossing it diagonally.
    """

    center: tuple[float, float]
    length: float
    width: float
    period: float
    heading: float = 0.0
    duration: float | None = None

    kind = "figure8"
    motion_end = None

    def sample(self, t: float) -> Reference:
        w = _TWO_PI / self.period
        ha, hb = 0.5 * self.length, 0.5 * self.width
        s1, c1 = math.sin(w * t), math.cos(w * t)
        s2, c2 = math.sin(2 * w * t), math.cos(2 * w * t)
        a, da, dda = ha * s1, ha * w * c1, -ha * w * w * s1
        b, db, ddb = hb * s2, 2 * hb * w * c2, -4 * hb * w * w * s2
        ch, sh = math.cos(self.heading), math.sin(self.heading)
        return Reference(self.center[0] + a * ch - b * sh, self.center[1] + a * sh + b * ch,
                         da * ch - db * sh, da * sh + db * ch,
                         dda * ch - ddb * sh, dda * sh + ddb * ch)


# --------------------------------------------------------------------------- polyline


@dataclass(frozen=True)
class SpeedProfile:
    """Distance along a path against time: rest -> ``speed`` -> rest over ``distance`` metres.

    Each ramp is half a cosine in speed, v = V/2 (1 - cos(pi t / T)), T = pi V / (2 A), so the
    acceleration (peak A) is continuous and zero at rest and at cruise. ``distance`` may be
    infinite (a closed path driven until the mission ends: no ramp down).
    """

    speed: float
    accel: float
    distance: float

    @property
    def ramp_time(self) -> float:
        return math.pi * self.speed / (2.0 * self.accel)

    @property
    def ramp_distance(self) -> float:
        return 0.5 * self.speed * self.ramp_time

    @property
    def end_time(self) -> float:
        return self.distance / self.speed + self.ramp_time

    def at(self, t: float) -> tuple[float, float, float]:
        """(s, s', s'') at time t."""
        V, T = self.speed, self.ramp_time
        if t <= 0.0:
            return 0.0, 0.0, 0.0
        k = math.pi / T
        if t < T:
            return (0.5 * V * (t - math.sin(k * t) / k), 0.5 * V * (1.0 - math.cos(k * t)),
                    0.5 * V * k * math.sin(k * t))
        cruise_end = self.distance / V   # start of the ramp down (infinite: never)
        if t <= cruise_end:
            return self.ramp_distance + V * (t - T), V, 0.0
        tau = t - cruise_end
        if tau < T:
            s0 = self.distance - self.ramp_distance
            return (s0 + 0.5 * V * (tau + math.sin(k * tau) / k),
                    0.5 * V * (1.0 + math.cos(k * tau)), -0.5 * V * k * math.sin(k * tau))
        return self.distance, 0.0, 0.0


@dataclass(frozen=True)
class _Piece:
    """A piece of constant curvature: a straight side (kappa 0) or an arc (kappa = +-1/r)."""

    s0: float                 # arc length where the piece starts
    length: float
    x0: float
    y0: float
    heading0: float
    kappa: float              # > 0 turns clockwise seen from above (north towards east)

    def at(self, u: float) -> tuple[float, float, float]:
        """(x, y, heading) at distance u into the piece."""
        h = self.heading0 + self.kappa * u
        if self.kappa == 0.0:
            return self.x0 + u * math.cos(h), self.y0 + u * math.sin(h), h
        r = 1.0 / self.kappa
        return (self.x0 + r * (math.sin(h) - math.sin(self.heading0)),
                self.y0 - r * (math.cos(h) - math.cos(self.heading0)), h)


# A turn sharper than this is a reversal: no arc of positive radius joins the two sides.
MAX_CORNER_TURN = math.radians(179.0)


@dataclass(frozen=True)
class Polyline:
    """Straight sides through ``points`` joined by tangent arcs, driven at ``speed``.

    Corners: each interior point (and every point of a ``closed`` polyline) is replaced by an arc
    of radius ``corner_radius`` tangent to both sides; the path passes inside the point, at
    distance r (1/cos(turn/2) - 1) from it. With ``shrink_corners`` a radius too large for short
    sides is reduced to fit (imported plans); without it, that is an error. Speed: see
    :class:`SpeedProfile`; an open path starts at ``points[0]`` at rest and ends at
    ``points[-1]`` at rest. A closed path starts where the arc at ``points[0]`` meets the first
    side and runs ``laps`` laps (None: for ever, no ramp down).
    """

    points: tuple[tuple[float, float], ...]
    speed: float
    corner_radius: float = 1.0
    accel: float = 0.5
    closed: bool = False
    laps: float | None = None
    shrink_corners: bool = False
    duration: float | None = None
    _pieces: tuple[_Piece, ...] = field(init=False, repr=False, compare=False)
    _starts: tuple[float, ...] = field(init=False, repr=False, compare=False)
    _profile: SpeedProfile = field(init=False, repr=False, compare=False)
    _radii: tuple[float, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        pieces, radii = _build_pieces(self.points, self.corner_radius, self.closed,
                                      self.shrink_corners)
        length = pieces[-1].s0 + pieces[-1].length
        if self.closed:
            distance = math.inf if self.laps is None else self.laps * length
        else:
            distance = length
        profile = SpeedProfile(self.speed, self.accel, distance)
        if 2.0 * profile.ramp_distance > distance:
            raise PathError("speed", (
                f"the path is {distance:.3g} m long, too short to reach {self.speed:g} m/s and "
                f"stop again at accel {self.accel:g} m/s^2 (needs "
                f"{2 * profile.ramp_distance:.3g} m): lower the speed or raise accel"))
        object.__setattr__(self, "_pieces", tuple(pieces))
        object.__setattr__(self, "_starts", tuple(p.s0 for p in pieces))
        object.__setattr__(self, "_profile", profile)
        object.__setattr__(self, "_radii", tuple(radii))

    @property
    def kind(self) -> str:
        return "line" if len(self.points) == 2 and not self.closed else "polyline"

    @property
    def length(self) -> float:
        """Length of the path (one lap for a closed one), metres."""
        last = self._pieces[-1]
        return last.s0 + last.length

    @property
    def period(self) -> float | None:
        return self.length / self.speed if self.closed else None

    @property
    def motion_end(self) -> float | None:
        end = self._profile.end_time
        return end if math.isfinite(end) else None

    @property
    def corner_radii(self) -> tuple[float, ...]:
        """The radius used at each rounded corner (after any shrinking)."""
        return self._radii

    def peaks(self) -> tuple[float, float]:
        """(peak speed, peak turn rate), exactly: the cruise speed and speed / smallest radius."""
        radius = min(self._radii, default=math.inf)
        return self.speed, self.speed / radius

    def sample(self, t: float) -> Reference:
        s, ds, dds = self._profile.at(t)
        if self.closed:
            s = s % self.length
        i = max(0, bisect.bisect_right(self._starts, s) - 1)
        piece = self._pieces[i]
        u = min(s - piece.s0, piece.length)
        x, y, h = piece.at(u)
        c, sn = math.cos(h), math.sin(h)
        k = piece.kappa * ds * ds
        return Reference(x, y, c * ds, sn * ds, c * dds - sn * k, sn * dds + c * k)


def _build_pieces(points: Sequence[tuple[float, float]], radius: float, closed: bool,
                  shrink: bool) -> tuple[list[_Piece], list[float]]:
    n = len(points)
    if n < (3 if closed else 2):
        raise PathError("points", f"needs at least {3 if closed else 2} points, has {n}")
    m = n if closed else n - 1                       # number of sides
    sides = []                                       # (length, heading) of side j: j -> j+1
    for j in range(m):
        (x0, y0), (x1, y1) = points[j], points[(j + 1) % n]
        length = math.hypot(x1 - x0, y1 - y0)
        if length < 1e-6:
            raise PathError(f"points[{(j + 1) % n}]",
                            f"coincides with points[{j}] {tuple(points[j])}")
        sides.append((length, math.atan2(y1 - y0, x1 - x0)))

    # Corner at point i joins side i-1 to side i: turn angle, tangent distance, radius.
    corners: dict[int, tuple[float, float, float]] = {}
    for i in (range(n) if closed else range(1, n - 1)):
        turn = _wrap(sides[i % m][1] - sides[i - 1][1])
        if abs(turn) < 1e-9:
            continue
        if abs(turn) > MAX_CORNER_TURN:
            raise PathError(f"points[{i}]", f"the path turns back on itself at {tuple(points[i])} "
                                            f"(a {math.degrees(abs(turn)):.1f} deg turn)")
        tan_half = math.tan(abs(turn) / 2.0)
        r = radius
        if shrink:
            room = 0.5 * min(sides[i - 1][0], sides[i % m][0])
            r = min(r, room / tan_half)
        corners[i] = (turn, r * tan_half, r)
    for j in range(m):
        need = corners.get(j, (0, 0.0, 0))[1] + corners.get((j + 1) % n, (0, 0.0, 0))[1]
        if need > sides[j][0] * (1.0 + 1e-9):
            tans = sum(math.tan(abs(corners[k][0]) / 2) for k in (j, (j + 1) % n) if k in corners)
            raise PathError("corner_radius", (
                f"{radius:g} m is too large for the {sides[j][0]:.3g} m side from points[{j}] "
                f"to points[{(j + 1) % n}]: its rounded corners need {need:.3g} m; use at most "
                f"{sides[j][0] / tans:.3g} m"))

    pieces: list[_Piece] = []
    s = 0.0

    def add(length: float, x: float, y: float, heading: float, kappa: float) -> None:
        nonlocal s
        if length > 1e-12:
            pieces.append(_Piece(s, length, x, y, heading, kappa))
            s += length

    for j in range(m):
        length, heading = sides[j]
        d_start = corners[j][1] if j in corners else 0.0
        end = (j + 1) % n
        d_end = corners[end][1] if end in corners else 0.0
        x0, y0 = points[j]
        c, sn = math.cos(heading), math.sin(heading)
        add(length - d_start - d_end, x0 + d_start * c, y0 + d_start * sn, heading, 0.0)
        if end in corners:
            turn, d, r = corners[end]
            xe, ye = points[end]
            add(r * abs(turn), xe - d * c, ye - d * sn, heading, math.copysign(1.0 / r, turn))
    return pieces, [corners[i][2] for i in sorted(corners)]


# --------------------------------------------------------------------------- timed waypoints


@dataclass(frozen=True)
class TimedWaypoints:
    """A quintic spline through ``waypoints`` = ((t_i, x_i, y_i), ...), times strictly increasing.

    Open (default): velocity and acceleration are zero at the first and last waypoint, and the
    reference stands at the first point before t_0 and at the last one after t_n, so position,
    velocity and acceleration are continuous for all t. ``closed``: the last waypoint must repeat
    the first; the spline is periodic with period t_n - t_0 and repeats for ever after t_0.
    Each piece is a quintic in u = (t - t_i) / (t_{i+1} - t_i); the 6n coefficients per axis solve
    interpolation, C4 continuity at interior knots and the end (or periodicity) conditions.
    """

    waypoints: tuple[tuple[float, float, float], ...]
    closed: bool = False
    duration: float | None = None
    _coef: np.ndarray = field(init=False, repr=False, compare=False)
    _times: tuple[float, ...] = field(init=False, repr=False, compare=False)

    kind = "waypoints"
    MAX_POINTS = 200   # a dense 6n x 6n solve; enough for any hand-written mission

    def __post_init__(self):
        pts = self.waypoints
        if not 2 <= len(pts) <= self.MAX_POINTS:
            raise PathError("waypoints", f"needs 2 to {self.MAX_POINTS} waypoints, has {len(pts)}")
        for i in range(1, len(pts)):
            if not pts[i][0] > pts[i - 1][0]:
                raise PathError(f"waypoints[{i}]", (
                    f"time {pts[i][0]:g} s does not come after the previous waypoint's "
                    f"{pts[i - 1][0]:g} s (times must increase)"))
        if self.closed:
            if len(pts) < 3:
                raise PathError("waypoints", "a closed path needs at least 3 waypoints")
            if (pts[-1][1], pts[-1][2]) != (pts[0][1], pts[0][2]):
                raise PathError(f"waypoints[{len(pts) - 1}]", (
                    f"a closed path must end where it starts: ({pts[-1][1]:g}, {pts[-1][2]:g}) "
                    f"is not ({pts[0][1]:g}, {pts[0][2]:g})"))
        coef = _quintic_spline([p[0] for p in pts], [(p[1], p[2]) for p in pts], self.closed)
        if not np.all(np.isfinite(coef)):
            raise PathError("waypoints", "the spline through these waypoints is not finite "
                                         "(times too far apart or too close)")
        object.__setattr__(self, "_coef", coef)
        object.__setattr__(self, "_times", tuple(float(p[0]) for p in pts))

    @property
    def period(self) -> float | None:
        return self._times[-1] - self._times[0] if self.closed else None

    @property
    def motion_end(self) -> float | None:
        return None if self.closed else self._times[-1]

    def segment(self, t: float) -> int:
        """Index i of the piece between waypoints i and i+1 that time t falls in."""
        ts = self._times
        if self.closed and t >= ts[0]:
            t = ts[0] + (t - ts[0]) % (ts[-1] - ts[0])
        return min(max(bisect.bisect_right(ts, t) - 1, 0), len(ts) - 2)

    def where(self, t: float) -> str:
        """Where time t is, for error messages: the pair of waypoints around it."""
        i = self.segment(t)
        return (f"between waypoints[{i}] and [{i + 1}] "
                f"(t {self._times[i]:g}..{self._times[i + 1]:g} s)")

    def sample(self, t: float) -> Reference:
        ts = self._times
        if t < ts[0]:
            # Before the first waypoint's time the reference waits there (a closed path then
            # starts moving at t_0 with its lap velocity).
            return Reference(*map(float, self.waypoints[0][1:]))
        if self.closed:
            t = ts[0] + (t - ts[0]) % (ts[-1] - ts[0])
        elif t >= ts[-1]:
            return Reference(*map(float, self.waypoints[-1][1:]))
        i = min(max(bisect.bisect_right(ts, t) - 1, 0), len(ts) - 2)
        h = ts[i + 1] - ts[i]
        u = (t - ts[i]) / h
        out = []
        for axis in (0, 1):
            c = self._coef[axis, i]
            p = ((((c[5] * u + c[4]) * u + c[3]) * u + c[2]) * u + c[1]) * u + c[0]
            dp = (((5 * c[5] * u + 4 * c[4]) * u + 3 * c[3]) * u + 2 * c[2]) * u + c[1]
            ddp = ((20 * c[5] * u + 12 * c[4]) * u + 6 * c[3]) * u + 2 * c[2]
            out.append((float(p), float(dp) / h, float(ddp) / (h * h)))
        (x, vx, ax), (y, vy, ay) = out
        return Reference(x, y, vx, vy, ax, ay)


def _derivative_row(d: int, u: float) -> np.ndarray:
    """Coefficients of d^d/du^d of sum c_k u^k at u (u is 0 or 1)."""
    row = np.zeros(6)
    for k in range(d, 6):
        row[k] = math.perm(k, d) * (u ** (k - d))
    return row


def _quintic_spline(times: Sequence[float], values: Sequence[tuple[float, float]],
                    closed: bool) -> np.ndarray:
    """Coefficients, shape (2 axes, n pieces, 6), of the spline described in TimedWaypoints."""
    n = len(times) - 1
    h = np.diff(np.asarray(times, dtype=float))
    A = np.zeros((6 * n, 6 * n))
    b = np.zeros((6 * n, 2))
    row = 0
    for i in range(n):
        A[row, 6 * i: 6 * i + 6] = _derivative_row(0, 0.0)
        b[row] = values[i]
        A[row + 1, 6 * i: 6 * i + 6] = _derivative_row(0, 1.0)
        b[row + 1] = values[i + 1]
        row += 2
    joints = [(j - 1, j) for j in range(1, n)] + ([(n - 1, 0)] if closed else [])
    for left, right in joints:
        ratio = h[left] / h[right]
        for d in range(1, 5):
            # h_left^-d D_d(left, 1) = h_right^-d D_d(right, 0), scaled by h_left^d.
            A[row, 6 * left: 6 * left + 6] = _derivative_row(d, 1.0)
            A[row, 6 * right: 6 * right + 6] -= ratio ** d * _derivative_row(d, 0.0)
            row += 1
    if not closed:
        for d in (1, 2):
            A[row, 0:6] = _derivative_row(d, 0.0)
            A[row + 1, 6 * (n - 1): 6 * n] = _derivative_row(d, 1.0)
            row += 2
    try:
        coef = np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        return np.full((2, n, 6), np.nan)
    return coef.T.reshape(2, n, 6)


# --------------------------------------------------------------------------- placement


@dataclass(frozen=True)
class Placed:
    """``inner`` turned by ``yaw`` (from north towards east) about the origin, then moved to (x, y)."""

    inner: object
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    @property
    def duration(self) -> float | None:
        return self.inner.duration

    def sample(self, t: float) -> Reference:
        r = self.inner.sample(t)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return Reference(self.x + c * r.x - s * r.y, self.y + s * r.x + c * r.y,
                         c * r.vx - s * r.vy, s * r.vx + c * r.vy,
                         c * r.ax - s * r.ay, s * r.ax + c * r.ay)
