"""The paper's Section 5 experiment: six scenarios, four controllers, Figure 13's cost table.

Scenarios (Sections 5.1 and 5.2): the ellipse p_ref = [6 cos - sin, 2 cos + 3 sin](2 pi f_r t)

    f_r = 0.04, 0.08, 0.12 Hz with d_cen = 0          (Figures 4-9)
    d_cen = 0, 0.3, 0.6 m with f_r = 0.12 Hz           (Figures 10-12)

What the paper leaves unsaid, and we choose: actuator bandwidth w_c = 20 rad/s (``--w-c``), the
rover starts at the origin at rest heading along +x, 60 s per run, no command limits (the paper's
plant has none), plant integrated on a 1 ms grid (finer when the loop is faster).

Controllers, all on the same plant and the same speed law (:mod:`companion.core.limits`):

    pzc        the paper's filter + PZC law and gains (k_df 1000, lambda_f 120, k_dc 5, lambda_c 12)
    pzc_tuned  the filter + PZC law with the tuner's gains for this rate and w_c
    pid        the paper's PID baseline (k_P 3.5, k_I 0.5, k_D 0.5)
    kanayama   Kanayama's kinematic tracking law
    pzc_literal  (optional) the paper's gains with the literal speed law v_ref = |u_p| of eq. (20)

All 6 x 4 runs go through one vectorised :func:`companion.sim.batch.simulate` call: each controller
owns a slice of 6 vehicles, its tracker built by :func:`companion.core.controllers.build` (as
``simulate``, ``run`` and ``demo`` build theirs). Pure computation: no I/O, no clock.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..core import controllers
from ..core.filter import FilterGains
from ..core.limits import Limits
from ..core.pzc import PZCGains
from ..core.signals import Num
from ..core.tracker import Tracker
from ..core.trajectory import Ellipse
from .batch import SimConfig, simulate
from .plant import RoverParams

SCENARIOS: tuple[tuple[float, float], ...] = (
    (0.04, 0.0), (0.08, 0.0), (0.12, 0.0),      # Section 5.1: reference speed
    (0.12, 0.0), (0.12, 0.3), (0.12, 0.6),      # Section 5.2: d_cen (the first repeats 5.1's last)
)
CONTROLLERS = ("pzc", "pzc_tuned", "pid", "kanayama")
LITERAL = "pzc_literal"
DURATION = 60.0
DIVERGED_RMS = 1000.0   # m: steady RMS beyond this is a diverged run, not a tracking result


@dataclass(frozen=True)
class TableConfig:
    rate_hz: float = 1000.0
    w_c: float = 20.0
    duration: float = DURATION
    scenarios: tuple[tuple[float, float], ...] = SCENARIOS
    limits: Limits = Limits()
    trace_every: float | None = None    # s; set to keep traces for the figures
    with_literal: bool = False          # also run the paper's literal speed law (pzc_literal)

    @property
    def controllers(self) -> tuple[str, ...]:
        return CONTROLLERS + ((LITERAL,) if self.with_literal else ())


@dataclass
class TableResult:
    config: TableConfig
    tuned_source: str
    # controller -> per-scenario arrays
    f_cost: dict[str, np.ndarray]
    steady_rms: dict[str, np.ndarray]
    # controller -> trace dict (key -> array of shape (samples, scenarios)); empty without traces
    traces: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)

    def diverged(self, controller: str) -> np.ndarray:
        """Runs whose error blew up (non-finite, or a steady RMS beyond 1 km)."""
        rms = self.steady_rms[controller]
        return ~np.isfinite(rms) | (rms > DIVERGED_RMS)

    def average(self, controller: str, which: slice | list[int] = slice(None)) -> float:
        return float(np.mean(self.f_cost[controller][which]))

    def improvement_vs_pid(self, controller: str = "pzc") -> float:
        """1 - average f_cost / average PID f_cost (the paper's 37 %)."""
        return 1.0 - self.average(controller) / self.average("pid")

    def as_dict(self) -> dict:
        """The ``companion paper-table --json`` object."""
        c = self.config
        scenarios = []
        for i, (f_r, d_cen) in enumerate(c.scenarios):
            scenarios.append({"f_r": f_r, "d_cen": d_cen, "controllers": {
                name: {"f_cost": _number(self.f_cost[name][i]),
                       "steady_rms": _number(self.steady_rms[name][i]),
                       "diverged": bool(self.diverged(name)[i])} for name in c.controllers}})
        return {
            "rate_hz": c.rate_hz, "w_c": c.w_c, "duration_s": c.duration,
            "start": {"x": 0.0, "y": 0.0, "yaw": 0.0, "at_rest": True},
            "scenarios": scenarios,
            "average": {name: _number(self.average(name)) for name in c.controllers},
            "improvement_vs_pid": _number(self.improvement_vs_pid("pzc")),
            "improvement_vs_pid_tuned": _number(self.improvement_vs_pid("pzc_tuned")),
            "pzc_cost_spread": _number(np.max(self.f_cost["pzc"]) / np.min(self.f_cost["pzc"])),
            "pzc_tuned_source": self.tuned_source,
        }


def _number(value: Num) -> float | None:
    """A JSON-safe float: None for NaN or infinity (strict JSON has neither)."""
    value = float(value)
    return value if np.isfinite(value) else None


def run_table(config: TableConfig, tuned: tuple[FilterGains, PZCGains], tuned_source: str,
              progress: Callable[[float], None] | None = None,
              only: tuple[str, ...] | None = None) -> TableResult:
    """Simulate every scenario with every controller (or the controllers ``only`` names) at once.

    Partial tables from ``only`` runs (e.g. in parallel processes) join with :func:`merge`.
    """
    n_s = len(config.scenarios)
    f_r = np.array([s[0] for s in config.scenarios], dtype=float)
    d_cen = np.array([s[1] for s in config.scenarios], dtype=float)
    lim = config.limits
    names = config.controllers if only is None else tuple(only)
    # Controllers that share a tracker class run as one vectorised tracker over their slices:
    # pzc and pzc_tuned are one PZCTracker with per-vehicle gains (half the per-step overhead).
    blocks: list[tuple[tuple[str, ...], Tracker]] = []
    pzc_names = [k for k in ("pzc", "pzc_tuned") if k in names]
    paper = (FilterGains(), PZCGains())
    sets = {"pzc": paper, "pzc_tuned": tuned}
    if len(pzc_names) > 1 and tuned[1].speed_law == paper[1].speed_law:
        blocks.append((tuple(pzc_names),
                       stacked_pzc([sets[k] for k in pzc_names], n_s, lim)))
    else:
        blocks += [((k,), controllers.build("pzc", lim, filter_gains=sets[k][0],
                                            pzc_gains=sets[k][1], n=n_s)) for k in pzc_names]
    for name in ("pid", "kanayama"):       # the baselines fly their own default gains
        if name in names:
            blocks.append(((name,), controllers.build(name, lim, n=n_s)))
    if LITERAL in names:
        blocks.append(((LITERAL,), controllers.build(
            "pzc", lim, filter_gains=FilterGains(), pzc_gains=PZCGains(speed_law="paper"), n=n_s)))

    groups: list[tuple[Tracker, slice]] = []
    slices: dict[str, slice] = {}
    start = 0
    for block_names, tracker in blocks:
        groups.append((tracker, slice(start, start + n_s * len(block_names))))
        for name in block_names:
            slices[name] = slice(start, start + n_s)
            start += n_s
    n = start
    order = [name for block_names, _ in blocks for name in block_names]
    plant = RoverParams(d_cen=np.tile(d_cen, len(order)), w_c=config.w_c)
    reference = Ellipse.paper(np.tile(f_r, len(order)))
    sim = SimConfig(duration=config.duration, control_rate=config.rate_hz,
                    trace_every=config.trace_every)
    result = simulate(groups, plant, reference, n, sim, progress)
    f_cost = {name: np.asarray(result.f_cost[sl]) for name, sl in slices.items()}
    rms = {name: np.asarray(result.steady_rms[sl]) for name, sl in slices.items()}
    traces = {}
    if result.trace:
        for name, sl in slices.items():
            traces[name] = {k: (v if k == "t" else v[:, sl]) for k, v in result.trace.items()}
    return TableResult(config, tuned_source, f_cost, rms, traces)


def merge(parts: list[TableResult]) -> TableResult:
    """One table from partial tables of the same configuration."""
    first = parts[0]
    out = TableResult(first.config, first.tuned_source, {}, {}, {})
    for part in parts:
        out.f_cost.update(part.f_cost)
        out.steady_rms.update(part.steady_rms)
        out.traces.update(part.traces)
    return out


def stacked_pzc(gain_sets: list[tuple[FilterGains, PZCGains]], n_each: int,
                limits: Limits) -> Tracker:
    """One PZC tracker for ``len(gain_sets) * n_each`` vehicles, gain set i on the i-th block.

    The gain sets must share a speed law (it is a branch, not a number).
    """
    def col(values: Sequence[Num]) -> np.ndarray:
        return np.repeat(np.asarray(values, dtype=float), n_each)

    fgs = [fg for fg, _ in gain_sets]
    pgs = [pg for _, pg in gain_sets]
    yaw = [pg._yaw_pair() for pg in pgs]
    return controllers.build(
        "pzc", limits,
        filter_gains=FilterGains(col([f.k_df for f in fgs]), col([f.lambda_f for f in fgs])),
        pzc_gains=PZCGains(col([p.k_dc for p in pgs]), col([p.lambda_c for p in pgs]),
                           k_dc_yaw=col([k for k, _ in yaw]),
                           lambda_c_yaw=col([lam for _, lam in yaw]),
                           velocity_ff=col([float(p.velocity_ff) for p in pgs]),
                           heading_rate_ff=col([float(p.heading_rate_ff) for p in pgs]),
                           accel_ff=col([float(p.accel_ff) for p in pgs]),
                           lead_tau=col([float(p.lead_tau) for p in pgs]),
                           lead_max_gain=col([float(p.lead_max_gain) for p in pgs]),
                           speed_law=pgs[0].speed_law),
        n=len(gain_sets) * n_each)
