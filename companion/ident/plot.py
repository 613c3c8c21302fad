"""Figures of a fit: measured against simulated speed and turn rate, with the setpoints.

matplotlib on the Agg backend (files only), imported when a figure is drawn.
"""

from __future__ import annotations

from pathlib import Path

from ..sim.plant import RoverParams
from .fit import simulate
from .series import Series


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_fit(series: Series, params: RoverParams, path: Path, title: str) -> str:
    """One PNG, two panels (speed, turn rate): setpoint, measured, model. Returns its path."""
    plt = _pyplot()
    v_sim, w_sim = simulate(params, series)
    t = series.t - series.t[0]
    fig, axes = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True)
    for ax, cmd, meas, sim, unit, what in (
            (axes[0], series.speed_cmd, series.speed, v_sim, "m/s", "speed along heading"),
            (axes[1], series.yaw_rate_cmd, series.yaw_rate, w_sim, "rad/s", "turn rate")):
        ax.step(t, cmd, where="post", color="0.6", lw=0.8, label="setpoint")
        ax.plot(t, meas, color="tab:blue", lw=1.0, label="measured")
        ax.plot(t, sim, color="tab:red", lw=1.0, ls="--", label="model")
        ax.set_ylabel(f"{what} ({unit})")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[1].set_xlabel("time (s)")
    axes[0].set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)
