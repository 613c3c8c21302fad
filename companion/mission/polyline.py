"""Polylines: straight sides joined by tangent arcs, driven from rest to rest.

Corners: every interior point (every point of a closed polyline) is replaced by a circular arc of
radius ``corner_radius`` tangent to both sides (a fillet), so the velocity is continuous and the
turn rate finite (speed / radius); the acceleration jumps by speed^2/radius where an arc begins
or ends. Speed along the path: :class:`SpeedProfile`, a raised-cosine ramp from rest to cruise
and back, so velocity and along-path acceleration are continuous.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from ..core.signals import Reference
from .paths import PathError

_TWO_PI = 2.0 * math.pi


def _wrap(angle: float) -> float:
    return (angle + math.pi) % _TWO_PI - math.pi


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
        pieces, radii = build_pieces(self.points, self.corner_radius, self.closed,
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
        return reference_at(self._pieces, self._starts, s, ds, dds)


def reference_at(pieces: Sequence[_Piece], starts: Sequence[float], s: float, ds: float,
                 dds: float) -> Reference:
    """The reference ``s`` metres along ``pieces`` (their ``s0`` in ``starts``), moving at
    ``ds`` and speeding up at ``dds`` along the path: the tangent's velocity and acceleration
    plus the curvature's ds^2 kappa across it."""
    piece = pieces[max(0, bisect.bisect_right(starts, s) - 1)]
    x, y, h = piece.at(min(max(s - piece.s0, 0.0), piece.length))
    c, sn = math.cos(h), math.sin(h)
    k = piece.kappa * ds * ds
    return Reference(x, y, c * ds, sn * ds, c * dds - sn * k, sn * dds + c * k)


def build_pieces(points: Sequence[tuple[float, float]], radius: float, closed: bool,
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
