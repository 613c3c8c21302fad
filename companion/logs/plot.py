"""The paper's figures from a flight log (:class:`companion.logs.logread.Flight`), as PNG files.

Same style as :mod:`companion.mission.plot`: map view east to the right, north up, equal
scales; matplotlib on the Agg backend (files only).

* ``path.png``: path against reference (map), and |p_ref - p| over time;
* ``xy.png``: x and y against time, with the reference;
* ``speed_yaw_rate.png``: measured speed and turn rate against the setpoints;
* ``filter_errors.png``: measured minus filtered x, y and yaw (the companion's CSV only).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..mission.plot import _pyplot
from .logread import Flight


def plot_flight(flight: Flight, out_dir: str | Path, title: str) -> list[str]:
    plt = _pyplot()
    out = Path(out_dir)
    paths: list[str] = []

    def save(fig, name: str) -> None:
        fig.suptitle(title, fontsize=10)
        fig.tight_layout()
        path = out / name
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(str(path))

    f = flight
    has_ref = f.x_ref is not None and f.mission_t is not None
    t = f.mission_t if has_ref and f.mission_t is not None else f.t - f.t[0]
    t_label = "mission time (s)" if has_ref else "vehicle time since the first sample (s)"

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 5.5))
    if has_ref:
        ax.plot(f.y_ref, f.x_ref, "--", color="gray", label="reference")
    ax.plot(f.y, f.x, "-", color="tab:blue", lw=1.2, label="rover (measured)")
    ax.plot(f.y[0], f.x[0], "^", color="black", label="start")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    if has_ref:
        ax2.plot(t, np.hypot(f.x_ref - f.x, f.y_ref - f.y), color="tab:red")
        ax2.set_ylabel("|p_ref - p| (m)")
    else:
        ax2.text(0.5, 0.5, "no reference in this log\n(give --mission FILE)", ha="center",
                 va="center", transform=ax2.transAxes)
    ax2.set_xlabel(t_label)
    ax2.grid(True, alpha=0.3)
    save(fig, "path.png")

    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    for ax, name, meas, ref in ((axes[0], "x (north, m)", f.x, f.x_ref),
                                (axes[1], "y (east, m)", f.y, f.y_ref)):
        if ref is not None:
            ax.plot(t, ref, "--", color="gray", label="reference")
        ax.plot(t, meas, "-", color="tab:blue", label="measured")
        ax.set_ylabel(name)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[1].set_xlabel(t_label)
    save(fig, "xy.png")

    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    cmd_t = None
    if f.cmd_t is not None and len(f.cmd_t):
        cmd_t = (np.interp(f.cmd_t, f.t, t) if has_ref else f.cmd_t - f.t[0])
    axes[0].plot(t, f.speed, color="tab:blue", label="measured")
    axes[1].plot(t, f.yaw_rate, color="tab:blue", label="measured")
    if cmd_t is not None:
        axes[0].plot(cmd_t, f.speed_cmd, color="tab:orange", lw=0.8, label="setpoint")
        if f.yaw_rate_cmd is not None and np.isfinite(f.yaw_rate_cmd).any():
            axes[1].plot(cmd_t, f.yaw_rate_cmd, color="tab:orange", lw=0.8, label="setpoint")
    axes[0].set_ylabel("speed (m/s)")
    axes[1].set_ylabel("yaw rate (rad/s)")
    axes[1].set_xlabel(t_label)
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    save(fig, "speed_yaw_rate.png")

    if f.x_hat is not None:
        fig, axes = plt.subplots(3, 1, figsize=(10, 7.5), sharex=True)
        yaw_err = np.remainder(f.yaw - f.yaw_hat + np.pi, 2 * np.pi) - np.pi
        for ax, name, err in ((axes[0], "x - x_hat (m)", f.x - f.x_hat),
                              (axes[1], "y - y_hat (m)", f.y - f.y_hat),
                              (axes[2], "yaw - yaw_hat (rad)", yaw_err)):
            ax.plot(t, err, color="tab:purple", lw=0.8)
            ax.set_ylabel(name)
            ax.grid(True, alpha=0.3)
        axes[2].set_xlabel(t_label)
        save(fig, "filter_errors.png")
    return paths
