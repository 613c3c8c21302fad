"""Routes: straight sides and arcs driven at the speed each piece allows, from rest to rest.

A :class:`Route` is the path of a :class:`~companion.mission.polyline.Polyline` (straight sides
joined by tangent arcs, :func:`~companion.mission.polyline.build_pieces`) with a speed that
changes along it, where a polyline keeps one speed for the whole path. Each piece has a speed
limit: the straight speed on a side; on an arc of radius r also the turn-rate limit times r and
the lateral-acceleration limit's sqrt(a_lat r), so a swath is driven fast and the turn at its end
slowly. The speed law is the classic forward-backward pass of time-optimal path following
(Bobrow, Dubowsky and Gibson 1985; Shin and McKay 1985) with piecewise-constant limits, solved
exactly per piece: the speed at each joint is the lower of its two pieces' limits, lowered
forwards and backwards until the along-path acceleration limit can reach it; within a piece
the speed rises, cruises at the piece's limit, and falls (a trapezoid in time, or a
triangle on a short piece), each change of speed along half a cosine so the along-path
acceleration is continuous (what the steps of a plain trapezoid cost on ArduPilot SITL:
docs/benchmarks.md, the field). The route starts and ends at rest. Where an arc meets a straight the curvature, and so the lateral acceleration v^2 kappa,
still steps: it is small at the turns' speeds.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from ..core.signals import Reference
from .coverage import FieldCover
from .paths import PathError
from .polyline import build_pieces, reference_at


@dataclass(frozen=True)
class RouteLimits:
    """What the time law keeps to: speed on a straight, turn rate and lateral acceleration on
    an arc, along-path acceleration everywhere."""

    speed: float                 # m/s on straight pieces
    turn_rate: float = 0.5       # rad/s: speed on an arc of radius r at most turn_rate * r
    lateral_accel: float = 0.5   # m/s^2: speed on an arc at most sqrt(lateral_accel * r)
    accel: float = 0.5           # m/s^2 along the path, speeding up and slowing down

    def on(self, kappa: float) -> float:
        """The speed limit of a piece of curvature ``kappa`` (1/m; 0 for a straight)."""
        if kappa == 0.0:
            return self.speed
        r = 1.0 / abs(kappa)
        return min(self.speed, self.turn_rate * r, math.sqrt(self.lateral_accel * r))


@dataclass(frozen=True)
class _Phase:
    """From time ``t0`` for ``duration`` s: the speed goes from ``v0`` to ``v0 + dv`` along half
    a cosine, v = v0 + dv/2 (1 - cos(pi tau / T)), so the acceleration (peak pi dv / 2T) is
    continuous and zero where the phase begins and ends; dv = 0 is a cruise."""

    t0: float
    s0: float
    v0: float
    dv: float
    duration: float

    def at(self, tau: float) -> tuple[float, float, float]:
        """(s, s', s'') ``tau`` s into the phase."""
        if self.dv == 0.0:
            return self.s0 + self.v0 * tau, self.v0, 0.0
        k = math.pi / self.duration
        half = 0.5 * self.dv
        return (self.s0 + self.v0 * tau + half * (tau - math.sin(k * tau) / k),
                self.v0 + half * (1.0 - math.cos(k * tau)), half * k * math.sin(k * tau))


def speed_law(lengths: Sequence[float], limits: Sequence[float], accel: float
              ) -> tuple[list[_Phase], list[float]]:
    """The phases of the time law over pieces of these ``lengths`` and speed ``limits`` with a
    peak along-path acceleration ``accel``, and the peak speed reached on each piece (see the
    module docstring).

    A raised-cosine change of speed by dv at peak acceleration A takes T = pi dv / (2 A) and
    covers (v0 + v1) / 2 T: exactly what a constant acceleration of 2 A / pi would, so the pass
    runs at that mean acceleration and each change is then shaped as the cosine."""
    n = len(lengths)
    mean = 2.0 * accel / math.pi
    joint = [0.0] + [min(limits[k - 1], limits[k]) for k in range(1, n)] + [0.0]
    for k in range(1, n + 1):                         # forwards: what accel can reach
        joint[k] = min(joint[k], math.sqrt(joint[k - 1] ** 2 + 2.0 * mean * lengths[k - 1]))
    for k in range(n - 1, -1, -1):                    # backwards: what accel can stop from
        joint[k] = min(joint[k], math.sqrt(joint[k + 1] ** 2 + 2.0 * mean * lengths[k]))
    phases: list[_Phase] = []
    peaks: list[float] = []
    t = s = end = 0.0
    for k in range(n):
        v0, v1, length = joint[k], joint[k + 1], lengths[k]
        top = min(limits[k], math.sqrt(mean * length + 0.5 * (v0 * v0 + v1 * v1)))
        peaks.append(top)
        d_up = (top * top - v0 * v0) / (2.0 * mean)
        d_down = (top * top - v1 * v1) / (2.0 * mean)
        cruise = max(0.0, length - d_up - d_down)
        for v_from, dv, duration, distance in (
                (v0, top - v0, (top - v0) / mean, d_up),
                (top, 0.0, cruise / top if top > 0 else 0.0, cruise),
                (top, v1 - top, (top - v1) / mean, d_down)):
            if duration > 1e-12:
                phases.append(_Phase(t, s, v_from, dv, duration))
                t += duration
                s += distance
        end += length
        s = end           # the pieces' own lengths fix where the next begins (no drift)
    phases.append(_Phase(t, end, 0.0, 0.0, math.inf))   # at rest at the end, for ever
    return phases, peaks


@dataclass(frozen=True)
class Route:
    """Straight sides through ``points`` joined by arcs of ``corner_radius`` (shrunk to fit a
    short side), driven by :func:`speed_law` under ``limits``; an open path from rest at
    ``points[0]`` to rest at ``points[-1]``. ``kind`` names it in summaries (a field's route:
    "field")."""

    points: tuple[tuple[float, float], ...]
    limits: RouteLimits
    corner_radius: float = 1.0
    kind: str = "route"
    duration: float | None = None
    note: str = field(default="", compare=False)   # what planned it said (mission check)
    cover: FieldCover | None = field(default=None, compare=False)   # a field's: what to cover
    _pieces: tuple = field(init=False, repr=False, compare=False)
    _starts: tuple[float, ...] = field(init=False, repr=False, compare=False)
    _phases: tuple[_Phase, ...] = field(init=False, repr=False, compare=False)
    _times: tuple[float, ...] = field(init=False, repr=False, compare=False)
    _peaks: tuple[float, float] = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        lim = self.limits
        for name in ("speed", "turn_rate", "lateral_accel", "accel"):
            value = getattr(lim, name)
            if not (math.isfinite(value) and value > 0):
                raise PathError(name, f"must be a positive number, not {value!r}")
        pieces, _radii = build_pieces(self.points, self.corner_radius, False, True)
        caps = [lim.on(p.kappa) for p in pieces]
        phases, tops = speed_law([p.length for p in pieces], caps, lim.accel)
        peak_rate = max((v * abs(p.kappa) for v, p in zip(tops, pieces, strict=True)),
                        default=0.0)
        object.__setattr__(self, "_pieces", tuple(pieces))
        object.__setattr__(self, "_starts", tuple(p.s0 for p in pieces))
        object.__setattr__(self, "_phases", tuple(phases))
        object.__setattr__(self, "_times", tuple(p.t0 for p in phases))
        object.__setattr__(self, "_peaks", (max(tops, default=0.0), peak_rate))

    @property
    def length(self) -> float:
        last = self._pieces[-1]
        return last.s0 + last.length

    @property
    def period(self) -> None:
        return None

    @property
    def motion_end(self) -> float:
        return self._phases[-1].t0

    def peaks(self) -> tuple[float, float]:
        """(peak speed, peak turn rate), exactly: the highest speed the law reaches on any
        piece, and the highest speed times curvature on any arc."""
        return self._peaks

    def along(self, t: float) -> tuple[float, float, float]:
        """(s, s', s'') at time t."""
        if t <= 0.0:
            return 0.0, 0.0, 0.0
        phase = self._phases[bisect.bisect_right(self._times, t) - 1]
        return phase.at(min(t - phase.t0, phase.duration))

    def sample(self, t: float) -> Reference:
        return reference_at(self._pieces, self._starts, *self.along(t))

    def straights(self) -> list[tuple[tuple[float, float], tuple[float, float]]]:
        """The straight pieces as (start, end) points, in the order driven."""
        out = []
        for p in self._pieces:
            if p.kappa == 0.0:
                x1, y1, _ = p.at(p.length)
                out.append(((p.x0, p.y0), (x1, y1)))
        return out

    def outline(self, step: float = 0.1) -> list[tuple[float, float]]:
        """Points along the path, at most ``step`` metres apart on its arcs (the straights'
        ends only): the path's shape for geometry checks and plots."""
        out = [(self._pieces[0].x0, self._pieces[0].y0)]
        for p in self._pieces:
            n = 1 if p.kappa == 0.0 else max(1, math.ceil(p.length / step))
            for i in range(1, n + 1):
                x, y, _ = p.at(p.length * i / n)
                out.append((x, y))
        return out

    def turn_count(self) -> int:
        return sum(1 for p in self._pieces if p.kappa != 0.0)
