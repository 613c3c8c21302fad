"""Pictures of missions: the path with time marks, and a simulated run against it.

Map view: east to the right, north up (the local NED frame seen from above), equal scales.
matplotlib runs on the Agg backend (files only, no display needed).
"""

from __future__ import annotations

import math

import numpy as np


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def sample_path(trajectory, duration: float, points: int = 2000) -> tuple[np.ndarray, ...]:
    ts = np.linspace(0.0, duration, points)
    refs = [trajectory.sample(float(t)) for t in ts]
    return ts, np.array([r.x for r in refs]), np.array([r.y for r in refs])


def _nice_step(duration: float) -> float:
    """About ten marks: 1, 2 or 5 times a power of ten seconds."""
    raw = max(duration / 10.0, 1e-3)
    base = 10 ** math.floor(math.log10(raw))
    return next(m * base for m in (1, 2, 5, 10) if m * base >= raw)


def plot_mission(mission, out: str, every: float | None = None) -> None:
    """Draw the mission's path to ``out`` (a "start"-frame path for a rover at the origin facing
    north)."""
    plt = _pyplot()
    trajectory = mission.anchored(0.0, 0.0, 0.0)
    ts, xs, ys = sample_path(trajectory, mission.duration)
    step = every or _nice_step(mission.duration)
    fig, ax = plt.subplots(figsize=(7, 7))
    ax.plot(ys, xs, "-", color="tab:blue", lw=1.5, label="reference path")
    marks = np.arange(0.0, mission.duration + 1e-9, step)
    for t in marks:
        r = trajectory.sample(float(t))
        ax.plot(r.y, r.x, "o", color="tab:orange", ms=4)
        ax.annotate(f"{t:g} s", (r.y, r.x), textcoords="offset points", xytext=(4, 4), fontsize=7)
    start = trajectory.sample(0.0)
    ax.plot(start.y, start.x, "s", color="tab:green", ms=8, label="reference start")
    if mission.frame == "start":
        ax.plot(0.0, 0.0, "^", color="black", ms=8, label="rover start (facing north)")
    else:
        ax.plot(0.0, 0.0, "+", color="black", ms=10, label="local origin (EKF origin)")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.set_title(f"{mission.name}: {mission.kind}, {mission.duration:.1f} s, marks every {step:g} s")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def plot_run(mission, log: dict[str, list[float]], out: str, title: str) -> None:
    """Reference against the simulated rover: map view and tracking error over time."""
    plt = _pyplot()
    t = np.asarray(log["t"])
    x, y = np.asarray(log["x"]), np.asarray(log["y"])
    xr, yr = np.asarray(log["x_ref"]), np.asarray(log["y_ref"])
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 5.5))
    ax.plot(yr, xr, "--", color="gray", label="reference")
    ax.plot(y, x, "-", color="tab:blue", label="rover")
    ax.plot(y[0], x[0], "^", color="black", label="rover start")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax2.plot(t, np.hypot(xr - x, yr - y), color="tab:red")
    ax2.set_xlabel("t (s)")
    ax2.set_ylabel("|p_ref - p| (m)")
    ax2.grid(True, alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
