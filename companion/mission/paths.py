"""Reference trajectories a mission file can ask for, beside the paper's :class:`Ellipse`.

Every kind gives position, velocity and acceleration analytically for any time ``t`` (seconds
after tracking starts) through ``sample(t) -> Reference``, on plain floats, as the live loop
needs. All are frozen dataclasses with a ``duration`` field (seconds of tracking, or None) and:

* ``period``: seconds per lap for periodic kinds, else None;
* ``motion_end``: the time after which an open path stands still at its end, else None.

Kinds (coordinates are (north, east) metres, headings radians from north towards east):

* :class:`Circle` (here): constant speed round a centre, clockwise or counter-clockwise seen
  from above.
* :class:`FigureEight` (here): the 1:2 Lissajous figure x = L/2 sin(wt), y = W/2 sin(2wt), rotated.
* :class:`companion.mission.polyline.Polyline` (and a straight line, a polyline of two points): straight
  sides joined by tangent circular arcs, raised-cosine speed ramps.
* :class:`companion.mission.spline.TimedWaypoints`: a quintic spline through (t_i, x_i, y_i).
* :class:`Placed` (here): any trajectory turned by a yaw and shifted (a mission given relative to
  the start pose, anchored at the vehicle's actual pose).

A kind that cannot be built as asked raises :class:`PathError` naming the parameter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..core.signals import Reference
from ..core.trajectory import Trajectory

_TWO_PI = 2.0 * math.pi


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


# --------------------------------------------------------------------------- placement


@dataclass(frozen=True)
class Placed:
    """``inner`` turned by ``yaw`` (from north towards east) about the origin, then moved to (x, y)."""

    inner: Trajectory
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
