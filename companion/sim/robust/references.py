"""The references: the paper's ellipses as the tuner's default ones, their peaks (turn rate,
speed, acceleration along the path) that decide which of them a vehicle can follow, and several
references stacked side by side for one batch."""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np

from ...core.pzc import reference_heading_rate
from ...core.signals import Reference
from ...core.trajectory import Ellipse, Trajectory

PAPER_F_R = (0.02, 0.04, 0.08, 0.12)


def _ellipse_samples(f_r: float, samples: int) -> list[Reference]:
    """One period of the paper's ellipse at ``f_r``, ``samples`` evenly spaced."""
    ellipse = Ellipse.paper(f_r)
    return [ellipse.sample(float(t)) for t in np.linspace(0.0, 1.0 / f_r, samples, endpoint=False)]


# The ellipse's peaks are remembered: every evaluation asks for the reference list again, and
# sampling them each time was a visible share of it (docs/design/robust-tuning.md).
@functools.lru_cache(maxsize=64)
def ellipse_turn_rate(f_r: float, samples: int = 2000) -> float:
    """The paper's ellipse's peak turn rate at ``f_r`` (rad/s; 1.13 at 0.08 Hz)."""
    return max(abs(reference_heading_rate(r)) for r in _ellipse_samples(f_r, samples))


@functools.lru_cache(maxsize=64)
def ellipse_speed(f_r: float, samples: int = 2000) -> float:
    """The paper's ellipse's peak speed at ``f_r`` (m/s; 3.18 at 0.08 Hz, 4.77 at 0.12 Hz)."""
    return max(math.hypot(r.vx, r.vy) for r in _ellipse_samples(f_r, samples))


@functools.lru_cache(maxsize=64)
def ellipse_path_accel(f_r: float, samples: int = 2000) -> float:
    """The paper's ellipse's peak acceleration along its path at ``f_r`` (m/s^2: the rate of
    change of its speed, (v . a) / |v|; 0.80 at 0.08 Hz, growing with f_r squared)."""
    return max(abs(r.vx * r.ax + r.vy * r.ay) / math.hypot(r.vx, r.vy)
               for r in _ellipse_samples(f_r, samples))


class StackedReference:
    """Several trajectories side by side: vehicle i follows ``trajs[which[i]]`` (one batch)."""

    def __init__(self, trajs: Sequence[Trajectory], which: np.ndarray):
        self.trajs, self.which = list(trajs), np.asarray(which)
        self.duration = None

    def sample(self, t: float) -> Reference:
        samples = [tr.sample(t) for tr in self.trajs]
        fields = ("x", "y", "vx", "vy", "ax", "ay")
        table = {f: np.array([float(getattr(s, f)) for s in samples]) for f in fields}
        return Reference(*(table[f][self.which] for f in fields))


def stacked_reference(refs: Sequence[Trajectory], n_cand: int, n_veh: int) -> Trajectory:
    """Vehicle order: candidate-major, then vehicle, then reference."""
    which = np.tile(np.arange(len(refs)), n_cand * n_veh)
    ellipses = [r for r in refs if isinstance(r, Ellipse)]
    if len(ellipses) == len(refs) and all(
            r.duration is None and (r.ax, r.bx, r.ay, r.by, r.cx, r.cy) == (6.0, -1.0, 2.0, 3.0, 0.0, 0.0)
            for r in ellipses):
        return Ellipse.paper(np.array([float(r.f_r) for r in ellipses])[which])
    return StackedReference(refs, which)
