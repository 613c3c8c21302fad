"""PNG equivalents of the paper's Figures 4-13 from a :class:`companion.sim.experiment.TableResult`.

Figures 4-9 use the three reference-speed scenarios (f_r = 0.04, 0.08, 0.12 Hz, d_cen = 0),
Figures 10-12 the three d_cen scenarios (0, 0.3, 0.6 m at f_r = 0.12 Hz), Figure 13 the cost table.
As in the paper, each figure compares the proposed controller (PZC, paper gains) with the PID;
the tuned PZC and Kanayama's law are drawn thinner for reference.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .experiment import TableResult

if TYPE_CHECKING:   # matplotlib loads only when a figure is drawn
    from matplotlib.figure import Figure

STYLE = {
    "pzc": dict(color="tab:blue", lw=1.6, label="PZC (paper gains)"),
    "pid": dict(color="tab:red", lw=1.2, label="PID (paper)"),
    "pzc_tuned": dict(color="tab:green", lw=0.9, label="PZC (tuned)"),
    "kanayama": dict(color="tab:purple", lw=0.9, label="Kanayama"),
    "pzc_literal": dict(color="tab:orange", lw=0.9, label="PZC, literal |u_p| law"),
}
REF = dict(color="k", lw=1.0, ls=":", label="reference")


def _columns(result: TableResult, want: list[tuple[float, float]]) -> list[int]:
    scen = list(result.config.scenarios)
    return [scen.index(w) for w in want if w in scen]


def _figure(n_cols: int, title: str) -> tuple[Figure, Any]:   # Any: an array of Axes
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, n_cols, figsize=(4.2 * n_cols, 3.8), squeeze=False)
    fig.suptitle(title)
    return fig, axes[0]


def _save(fig: Figure, path: Path) -> Path:
    import matplotlib.pyplot as plt
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _label(result: TableResult, col: int) -> str:
    f_r, d_cen = result.config.scenarios[col]
    return f"f_r = {f_r:g} Hz, d_cen = {d_cen:g} m"


def _paths(result: TableResult, cols: list[int], title: str, path: Path) -> Path:
    fig, axes = _figure(len(cols), title)
    for ax, col in zip(axes, cols, strict=True):
        tr = result.traces["pzc"]
        for name in result.traces:
            t = result.traces[name]
            ax.plot(t["x"][:, col], t["y"][:, col], **STYLE[name])
        ax.plot(tr["x_ref"][:, col], tr["y_ref"][:, col], zorder=5, **REF)
        ax.plot([0.0], [0.0], "ko", ms=4, zorder=6)
        # The paper's Cartesian axes: x across, y up (our x is north, y east).
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_title(_label(result, col), fontsize=9)
        ax.set_aspect("equal", adjustable="datalim")
    axes[0].legend(fontsize=7, loc="best")
    return _save(fig, path)


def _series(result: TableResult, cols: list[int], key: str, ref_key: str | None, ylabel: str,
            title: str, path: Path, names: tuple[str, ...] = ("pzc", "pid")) -> Path:
    fig, axes = _figure(len(cols), title)
    for ax, col in zip(axes, cols, strict=True):
        for name in names:
            if name not in result.traces:
                continue
            t = result.traces[name]
            ax.plot(t["t"], t[key][:, col], **STYLE[name])
        if ref_key is not None:
            tr = result.traces["pzc"]
            ax.plot(tr["t"], tr[ref_key][:, col], zorder=5, **REF)
        ax.set_xlabel("t [s]")
        ax.set_ylabel(ylabel)
        ax.set_title(_label(result, col), fontsize=9)
    axes[0].legend(fontsize=7, loc="best")
    return _save(fig, path)


def _filter_errors(result: TableResult, cols: list[int], title: str, path: Path) -> Path:
    fig, axes = _figure(len(cols), title)
    tr = result.traces["pzc"]
    for ax, col in zip(axes, cols, strict=True):
        for key, label in (("ex", "x - x_hat [m]"), ("ey", "y - y_hat [m]"),
                           ("eyaw", "phi - phi_hat [rad]")):
            ax.plot(tr["t"], tr[key][:, col], lw=0.9, label=label)
        ax.set_xlabel("t [s]")
        ax.set_title(_label(result, col), fontsize=9)
    axes[0].legend(fontsize=7, loc="best")
    return _save(fig, path)


def _cost_bars(result: TableResult, path: Path) -> Path:
    fig, axes = _figure(1, f"f_cost per scenario (Figure 13) at {result.config.rate_hz:g} Hz, "
                           f"w_c {result.config.w_c:g} rad/s")
    ax = axes[0]
    names = [n for n in STYLE if n in result.f_cost]
    labels = [f"{f:g} Hz\n{d:g} m" for f, d in result.config.scenarios]
    x = np.arange(len(labels))
    width = 0.8 / len(names)
    for i, name in enumerate(names):
        ax.bar(x + (i - (len(names) - 1) / 2) * width, result.f_cost[name], width,
               color=STYLE[name]["color"], label=STYLE[name]["label"])
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("f_cost [m s^0.5]")
    ax.legend(fontsize=7)
    fig.set_size_inches(8, 4)
    return _save(fig, path)


def plot_all(result: TableResult, out_dir: str | Path) -> list[Path]:
    """Write the figures into ``out_dir`` (created); returns the files written."""
    import matplotlib
    matplotlib.use("Agg")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if not result.traces:
        raise ValueError("the table was run without traces (TableConfig.trace_every)")
    speed = _columns(result, [(0.04, 0.0), (0.08, 0.0), (0.12, 0.0)])
    dcen = _columns(result, [(0.12, 0.0), (0.12, 0.3), (0.12, 0.6)])
    both = ("pzc", "pid")
    files = []
    if speed:
        files += [
            _paths(result, speed, "Figure 4: paths for three reference speeds", out / "fig04_paths.png"),
            _series(result, speed, "x", "x_ref", "x [m]", "Figure 5: x against time", out / "fig05_x.png"),
            _series(result, speed, "y", "y_ref", "y [m]", "Figure 6: y against time", out / "fig06_y.png"),
            _series(result, speed, "v", None, "v [m/s]", "Figure 7: linear speed", out / "fig07_speed.png", both),
            _series(result, speed, "omega", None, "omega [rad/s]", "Figure 8: yaw rate",
                    out / "fig08_yaw_rate.png", both),
            _filter_errors(result, speed, "Figure 9: filtering errors (PZC)", out / "fig09_filter_errors.png"),
        ]
    if dcen:
        files += [
            _paths(result, dcen, "Figure 10: paths for three d_cen", out / "fig10_paths_dcen.png"),
            _series(result, dcen, "x", "x_ref", "x [m]", "Figure 11: x against time (d_cen)",
                    out / "fig11_x_dcen.png"),
            _series(result, dcen, "y", "y_ref", "y [m]", "Figure 12: y against time (d_cen)",
                    out / "fig12_y_dcen.png"),
        ]
    files.append(_cost_bars(result, out / "fig13_cost.png"))
    return files
