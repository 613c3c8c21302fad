"""Timed waypoints: a quintic spline through (t_i, x_i, y_i), continuous in position, velocity
and acceleration (up to the fourth derivative between the ends)."""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..core.signals import Reference
from .paths import PathError


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
        if t < ts[0] or (t == ts[0] and not self.closed):
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
