"""Gain tuning by batch simulation: the paper's Remark 6, done by the machine.

Remark 6 tunes the four design parameters (k_df, lambda_f, k_dc, lambda_c) by "offline
iterations"; the conclusion names an offline optimisation as future work. Here a population of
candidate gain sets is simulated at once with :func:`companion.sim.batch.simulate` on several
reference speeds (the paper's ellipse at f_r = 0.04, 0.08 and 0.12 Hz: gains that are stable on a
fast reference can orbit a slow one, and the reverse), at the loop rate, actuator bandwidth and
limits of the real vehicle, and the search keeps the set with the lowest objective

    J = mean over references of f_cost   (f_cost = sqrt(int |p_ref - p|^2 dt), Section 5.3)

The search is a seeded random search followed by rounds of log-normal perturbation around the
best sets (a simple evolution strategy): no gradient, no model, just the simulator. It also
chooses the extensions of :mod:`companion.core.pzc` (separate yaw pair, velocity, heading-rate and
acceleration feed-forward, actuator lead) per candidate, so their worth is measured, not assumed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..core.filter import FilterGains
from ..core.limits import Limits
from ..core.pzc import PZCGains, PZCTracker
from ..core.trajectory import Ellipse
from .batch import SimConfig, simulate
from .gains import TunedGains
from .plant import RoverParams

# log-uniform search ranges: (low, high)
RANGES = {
    "k_df": (5.0, 2000.0),
    "lambda_f": (1.0, 300.0),
    "k_dc": (0.1, 60.0),
    "lambda_c": (0.1, 30.0),
    "k_dc_yaw": (0.1, 60.0),
    "lambda_c_yaw": (0.1, 30.0),
    "accel_ff": (0.01, 3.0),
    "lead_tau": (0.02, 3.0),
    "lead_max_gain": (1.0, 50.0),
}
FLAGS = ("velocity_ff", "heading_rate_ff", "separate_yaw", "use_accel_ff", "use_lead")


@dataclass(frozen=True)
class TuneConfig:
    rate_hz: float = 40.0
    w_c: float = 20.0
    d_cen: float = 0.0
    f_r: tuple[float, ...] = (0.04, 0.08, 0.12)
    duration: float = 60.0
    limits: Limits = Limits()
    max_accel: float = math.inf
    population: int = 256
    rounds: int = 4
    elite: int = 12
    seed: int = 1

    @property
    def vehicle(self) -> RoverParams:
        return RoverParams(d_cen=self.d_cen, w_c=self.w_c, max_speed=self.limits.max_speed,
                           max_yaw_rate=self.limits.max_yaw_rate, max_accel=self.max_accel)


@dataclass
class Candidates:
    """A population: one array per parameter, one entry per candidate."""

    params: dict[str, np.ndarray]
    flags: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(next(iter(self.params.values())))

    def gains(self, i: int) -> tuple[FilterGains, PZCGains]:
        p = {k: float(v[i]) for k, v in self.params.items()}
        f = {k: bool(v[i]) for k, v in self.flags.items()}
        separate = f["separate_yaw"]
        return (FilterGains(p["k_df"], p["lambda_f"]),
                PZCGains(p["k_dc"], p["lambda_c"],
                         k_dc_yaw=p["k_dc_yaw"] if separate else None,
                         lambda_c_yaw=p["lambda_c_yaw"] if separate else None,
                         velocity_ff=f["velocity_ff"], heading_rate_ff=f["heading_rate_ff"],
                         accel_ff=p["accel_ff"] if f["use_accel_ff"] else 0.0,
                         lead_tau=p["lead_tau"] if f["use_lead"] else 0.0,
                         lead_max_gain=p["lead_max_gain"] if f["use_lead"] else 1.0))

    def take(self, index: np.ndarray) -> Candidates:
        return Candidates({k: v[index] for k, v in self.params.items()},
                          {k: v[index] for k, v in self.flags.items()})

    @staticmethod
    def concat(parts: list[Candidates]) -> Candidates:
        return Candidates({k: np.concatenate([p.params[k] for p in parts]) for k in parts[0].params},
                          {k: np.concatenate([p.flags[k] for p in parts]) for k in parts[0].flags})


def seeds() -> Candidates:
    """Hand-picked starting points: the paper's gains in the paper's form and with every extension."""
    rows = [
        # k_df, lambda_f, k_dc, lambda_c, k_dc_yaw, lambda_c_yaw, accel_ff, lead_tau, lead_max_gain,
        # then the flags vff, hff, separate, use_accel_ff, use_lead
        (1000, 120, 5, 12, 5, 12, 0.05, 0.05, 1, 0, 0, 0, 0, 0),
        (1000, 120, 5, 12, 5, 12, 0.05, 0.05, 1, 1, 1, 0, 0, 0),
        (200, 40, 2, 1, 5, 3, 0.05, 0.05, 1, 1, 1, 1, 0, 0),
        (100, 20, 1, 0.5, 3, 2, 0.05, 0.05, 1, 1, 1, 1, 0, 0),
        (100, 20, 1, 0.5, 3, 2, 0.8, 0.8, 8, 1, 1, 1, 1, 1),
    ]
    a = np.array(rows, dtype=float)
    names = list(RANGES)
    return Candidates({k: a[:, i] for i, k in enumerate(names)},
                      {k: a[:, len(names) + i] for i, k in enumerate(FLAGS)})


def random_candidates(rng: np.random.Generator, n: int) -> Candidates:
    params = {k: np.exp(rng.uniform(math.log(lo), math.log(hi), n)) for k, (lo, hi) in RANGES.items()}
    flags = {k: rng.integers(0, 2, n).astype(float) for k in FLAGS}
    return Candidates(params, flags)


def perturb(rng: np.random.Generator, parents: Candidates, n: int, sigma: float) -> Candidates:
    pick = rng.integers(0, len(parents), n)
    child = parents.take(pick)
    for k, (lo, hi) in RANGES.items():
        child.params[k] = np.clip(child.params[k] * np.exp(sigma * rng.standard_normal(n)), lo, hi)
    for k in FLAGS:
        flip = rng.random(n) < 0.1
        child.flags[k] = np.where(flip, 1.0 - child.flags[k], child.flags[k])
    return child


def evaluate(cands: Candidates, cfg: TuneConfig,
             progress: Callable[[float], None] | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Simulate every candidate on every reference at once.

    Returns (objective per candidate, f_cost and steady RMS per candidate and reference).
    Unstable candidates (non-finite or exploding) get an infinite objective.
    """
    n_c, n_s = len(cands), len(cfg.f_r)
    n = n_c * n_s
    rep = lambda a: np.repeat(a, n_s)               # vehicle i*n_s + j = candidate i on reference j
    p, f = cands.params, cands.flags
    separate = f["separate_yaw"] > 0.5
    tracker = PZCTracker(
        FilterGains(rep(p["k_df"]), rep(p["lambda_f"])),
        PZCGains(rep(p["k_dc"]), rep(p["lambda_c"]),
                 k_dc_yaw=rep(np.where(separate, p["k_dc_yaw"], p["k_dc"])),
                 lambda_c_yaw=rep(np.where(separate, p["lambda_c_yaw"], p["lambda_c"])),
                 velocity_ff=rep(f["velocity_ff"]), heading_rate_ff=rep(f["heading_rate_ff"]),
                 accel_ff=rep(np.where(f["use_accel_ff"] > 0.5, p["accel_ff"], 0.0)),
                 lead_tau=rep(np.where(f["use_lead"] > 0.5, p["lead_tau"], 0.0)),
                 lead_max_gain=rep(np.where(f["use_lead"] > 0.5, p["lead_max_gain"], 1.0))),
        cfg.limits, n=n)
    vehicle = cfg.vehicle.with_(d_cen=np.full(n, cfg.d_cen))
    reference = Ellipse.paper(np.tile(np.asarray(cfg.f_r, dtype=float), n_c))
    sim = SimConfig(duration=cfg.duration, control_rate=cfg.rate_hz)
    with np.errstate(all="ignore"):
        result = simulate(tracker, vehicle, reference, n, sim, progress)
    cost = result.f_cost.reshape(n_c, n_s)
    rms = result.steady_rms.reshape(n_c, n_s)
    objective = cost.mean(axis=1)
    objective[~np.isfinite(objective)] = np.inf
    return objective, cost, rms


@dataclass
class TuneResult:
    gains: TunedGains
    cost_per_reference: list[float]
    steady_rms_per_reference: list[float]
    evaluated: int
    f_r: tuple[float, ...] = ()


def tune(cfg: TuneConfig, progress: Callable[[float], None] | None = None) -> TuneResult:
    """Search the gains; ``progress(fraction)`` over the whole search."""
    rng = np.random.default_rng(cfg.seed)
    population = Candidates.concat([seeds(), random_candidates(rng, cfg.population - len(seeds()))])
    best: Candidates | None = None
    best_obj = np.array([])
    evaluated = 0
    for r in range(cfg.rounds):
        def round_progress(frac: float, r: int = r) -> None:
            if progress is not None:
                progress((r + frac) / cfg.rounds)
        obj, _, _ = evaluate(population, cfg, round_progress)
        evaluated += len(population)
        pool = population if best is None else Candidates.concat([best, population])
        pool_obj = obj if best is None else np.concatenate([best_obj, obj])
        order = np.argsort(pool_obj)[:cfg.elite]
        best, best_obj = pool.take(order), pool_obj[order]
        sigma = 0.6 * 0.6 ** r
        population = perturb(rng, best, cfg.population, sigma)

    # Re-evaluate the winner alone to report its per-reference figures.
    assert best is not None   # cfg.rounds >= 1 (the command refuses fewer)
    winner = best.take(np.array([0]))
    obj, cost, rms = evaluate(winner, cfg)
    fg, pg = winner.gains(0)
    return TuneResult(
        TunedGains(fg, pg, rate_hz=cfg.rate_hz, w_c=cfg.w_c, d_cen=cfg.d_cen, cost=float(obj[0])),
        cost_per_reference=[float(v) for v in cost[0]],
        steady_rms_per_reference=[float(v) for v in rms[0]], evaluated=evaluated, f_r=tuple(cfg.f_r))
