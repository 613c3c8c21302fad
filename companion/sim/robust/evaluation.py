"""One evaluation: every candidate flown on every vehicle of the ensemble and every reference in
one batch (split across processes if given some), then the objective and the rejections."""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np

from ..batch import SimConfig, simulate
from ..plant import RoverParams
from ..tuning import Candidates
from .candidates import brake_scales, tracker
from .config import RobustConfig
from .ensemble import stack_params
from .references import stacked_reference

LIMIT_CYCLE_SHARE = 0.05     # yaw-rate setpoint at its limit in more of the second half: rejected


@dataclass
class Evaluation:
    objective: np.ndarray              # per candidate (inf: rejected)
    steady_rms: np.ndarray             # [candidate, vehicle, reference]
    f_cost: np.ndarray
    yaw_at_limit: np.ndarray
    chatter: np.ndarray                # speed TV + yaw-rate TV, per s
    rejected: np.ndarray               # per candidate: why ("" if kept)


def simulate_part(cands: Candidates, cfg: RobustConfig, vehicles: Sequence[RoverParams],
                  first: int, total: int, progress: Callable[[float], None] | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Candidates ``first`` .. ``first + len(cands)`` of a batch of ``total``: steady RMS,
    f_cost, share at the yaw-rate limit and chatter, each [candidate, vehicle, reference]. Each
    part draws the whole batch's noise (SimConfig.noise_slice), so a batch split across
    processes gives what it gives in one."""
    refs = [tr for _, tr in cfg.reference_list()]
    n_c, n_v, n_r = len(cands), len(vehicles), len(refs)
    n = n_c * n_v * n_r
    params = stack_params(vehicles, n_r, n_c)
    sim = SimConfig(duration=cfg.duration, control_rate=cfg.rate_hz, max_plant_dt=cfg.plant_dt,
                    tick=cfg.tick, noise_pos=cfg.noise_pos, noise_yaw=cfg.noise_yaw,
                    seed=cfg.seed, yaw_rate_limit=min(cfg.limits.max_yaw_rate,
                                                      float(np.min(params.max_yaw_rate))),
                    noise_slice=(total * n_v * n_r, first * n_v * n_r))
    with np.errstate(all="ignore"):
        result = simulate(tracker(cands, n_v * n_r, cfg.limits, brake_scales(cfg.vehicle),
                                   cfg.law_settings(), cfg.predict_delay), params,
                          stacked_reference(refs, n_c, n_v), n, sim, progress)
    shape = (n_c, n_v, n_r)
    return (np.asarray(result.steady_rms).reshape(shape),
            np.asarray(result.f_cost).reshape(shape),
            np.asarray(result.yaw_at_limit).reshape(shape),
            (np.asarray(result.speed_tv) + np.asarray(result.yaw_rate_tv)).reshape(shape))


# Below this many candidates a batch is not split (the step loop's fixed overhead per
# evaluation would dominate each part: docs/design/robust-tuning.md).
MIN_SPLIT = 16


def evaluate(cands: Candidates, cfg: RobustConfig, vehicles: Sequence[RoverParams],
             progress: Callable[[float], None] | None = None,
             pool: Executor | None = None, workers: int = 1) -> Evaluation:
    """Every candidate on every vehicle and reference. With a ``pool`` of ``workers - 1``
    processes the candidates are split ``workers`` ways, this process flying the first part;
    the figures are the same as in one batch (:func:`simulate_part`)."""
    n_c = len(cands)
    parts = 1 if pool is None else max(1, min(workers, n_c // MIN_SPLIT))
    bounds = [round(i * n_c / parts) for i in range(parts + 1)]
    assert pool is not None or parts == 1
    futures = [pool.submit(simulate_part, cands.take(np.arange(a, b)), cfg, vehicles, a, n_c)
               for a, b in itertools.pairwise(bounds[1:])] if pool is not None else []
    own = simulate_part(cands.take(np.arange(bounds[0], bounds[1])) if parts > 1 else cands,
                         cfg, vehicles, 0, n_c, progress)
    results = [own] + [f.result() for f in futures]
    rms, cost, at_limit, chatter = (np.concatenate([r[i] for r in results]) for i in range(4))
    finite = np.isfinite(rms) & np.isfinite(cost) & (rms < 1e3)
    rms_mean = np.where(finite, rms, np.inf).mean(axis=1)            # [cand, ref]
    cost_mean = np.where(finite, cost, np.inf).mean(axis=1)
    weights = cfg.reference_weights()               # sum / count: the mean where all are 1

    def weighted(per_ref: np.ndarray) -> np.ndarray:
        return (per_ref * weights).sum(axis=1) / weights.sum()

    objective = (weighted(np.log(rms_mean + cfg.rms_floor)) + 0.25 * weighted(np.log(cost_mean))
                 + cfg.chatter_weight * np.where(finite, chatter, np.inf).mean(axis=(1, 2)))
    rejected = np.full(n_c, "", dtype=object)
    cycling = (at_limit > LIMIT_CYCLE_SHARE).any(axis=(1, 2))
    if not cfg.limit_cycles:
        # the autopilot ignores the yaw-rate setpoint (PX4's u_p): its limit says nothing there
        cycling = np.zeros(n_c, dtype=bool)
    diverged = ~finite.all(axis=(1, 2))
    rejected[cycling] = "limit cycle"
    rejected[diverged] = "diverged"
    objective = np.where(cycling | diverged | ~np.isfinite(objective), np.inf, objective)
    return Evaluation(objective, rms, cost, at_limit, chatter, rejected)

