"""Reference trajectories p_ref(t) with analytic velocity and acceleration.

A trajectory is anything with ``sample(t) -> Reference`` (position, velocity, acceleration at time
``t`` seconds after tracking starts) and a ``duration`` (seconds, or ``None`` if it never ends).
Parameters may be numpy arrays, one value per vehicle, for batch simulation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from . import ops as _ops
from .signals import Num, Reference


class Trajectory(Protocol):
    # Read-only: the frozen dataclasses below (and mission.paths' wrappers) satisfy it too.
    @property
    def duration(self) -> float | None: ...

    def sample(self, t: float) -> Reference: ...


def _ops_for(*values: Num) -> _ops.Ops:
    return _ops.array if any(isinstance(v, np.ndarray) for v in values) else _ops.scalar


@dataclass(frozen=True)
class Ellipse:
    """x = ax cos(wt) + bx sin(wt) + cx, y = ay cos(wt) + by sin(wt) + cy with w = 2 pi f_r.

    :meth:`paper` is Section 5's reference: p_ref = [6 cos - sin, 2 cos + 3 sin].
    """

    f_r: Num
    ax: Num = 6.0
    bx: Num = -1.0
    ay: Num = 2.0
    by: Num = 3.0
    cx: Num = 0.0
    cy: Num = 0.0
    duration: float | None = None

    @classmethod
    def paper(cls, f_r: Num = 0.12, duration: float | None = None) -> Ellipse:
        return cls(f_r=f_r, duration=duration)

    def __post_init__(self) -> None:
        # Many vehicles usually share a few frequencies: take cos/sin once per distinct one.
        if isinstance(self.f_r, np.ndarray):
            freqs, index = np.unique(self.f_r, return_inverse=True)
            object.__setattr__(self, "_unique", (2.0 * math.pi * freqs, index))

    def _cos_sin(self, t: float) -> tuple[Num, Num]:
        unique = getattr(self, "_unique", None)
        if unique is not None:
            w, index = unique
            return np.cos(w * t)[index], np.sin(w * t)[index]
        m = _ops_for(self.ax, self.bx, self.ay, self.by)
        wt = 2.0 * math.pi * self.f_r * t
        return m.cos(wt), m.sin(wt)

    def sample(self, t: float) -> Reference:
        w = 2.0 * math.pi * self.f_r
        c, s = self._cos_sin(t)
        xc, xs = self.ax * c, self.bx * s   # x = xc + xs
        yc, ys = self.ay * c, self.by * s
        w2 = w * w
        return Reference(
            xc + xs + self.cx, yc + ys + self.cy,
            w * (self.bx * c - self.ax * s), w * (self.by * c - self.ay * s),
            -w2 * (xc + xs), -w2 * (yc + ys),
        )
