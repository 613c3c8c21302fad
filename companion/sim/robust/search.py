"""The search: seeded and random candidates, rounds of evaluation and perturbation around the
elite (:mod:`companion.sim.tuning`'s), the winner confirmed alone, and the tuned gains."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field, replace

import numpy as np

from ..gains import TunedGains
from ..plant import RoverParams
from ..tuning import Candidates
from .candidates import brake_scales, candidate_gains, drawn, perturbed, predict_seeds, seeds
from .config import RobustConfig
from .ensemble import ensemble
from .evaluation import Evaluation, evaluate
from .pool import workers


@dataclass
class RobustResult:
    gains: TunedGains
    objective: float
    references: list[str]
    nominal_steady_rms: list[float]            # the identified vehicle, per reference
    worst_steady_rms: list[float]              # the worst neighbour, per reference
    nominal_f_cost: list[float]
    worst_yaw_at_limit: float
    vehicles: list[RoverParams]
    evaluated: int
    rejected: dict[str, int] = field(default_factory=dict)


def rounds(cfg: RobustConfig, vehicles: Sequence[RoverParams], population: Candidates,
           rng: np.random.Generator, rejected: dict[str, int], total: int,
           progress: Callable[[float], None] | None, pool: Executor | None
           ) -> tuple[Candidates, np.ndarray, int]:
    """The rounds of :func:`tune`: evaluate, keep the elite, perturb; (the elite, best first,
    their objectives, and how many candidates were evaluated)."""
    best: Candidates | None = None
    evaluated = 0
    best_obj = np.array([])
    for r in range(cfg.rounds):
        def round_progress(f: float, r: int = r) -> None:
            if progress is not None:
                progress((r + f) / total)
        ev = evaluate(population, cfg, vehicles, None if progress is None else round_progress,
                      pool, cfg.workers)
        evaluated += len(population)
        for why in rejected:
            rejected[why] += int(np.sum(ev.rejected == why))
        merged = population if best is None else Candidates.concat([best, population])
        merged_obj = ev.objective if best is None else np.concatenate([best_obj, ev.objective])
        order = np.argsort(merged_obj)[:cfg.elite]
        best, best_obj = merged.take(order), merged_obj[order]
        population = perturbed(rng, best, cfg.population, 0.5 * 0.6 ** r,
                              cfg.predict_delay > 0)
    assert best is not None   # cfg.rounds >= 1 (the command refuses fewer)
    return best, best_obj, evaluated


def confirmed(best: Candidates, best_obj: np.ndarray, cfg: RobustConfig,
              vehicles: Sequence[RoverParams], progress: Callable[[float], None] | None
              ) -> tuple[Candidates, Evaluation]:
    """The best of the elite that holds again simulated on its own, and that evaluation.

    Each vehicle draws the noise of the whole batch it is simulated in, so a gain set at the
    edge of a limit cycle can hold in its round and not alone, and calibrate would stop with
    nothing robust while another of the elite holds both times (docs/design/robust-tuning.md).
    The winner that holds alone is taken as before; only where it does not does the next one
    get its turn."""
    failed: tuple[Candidates, Evaluation] | None = None
    for i in np.flatnonzero(np.isfinite(best_obj)):
        winner = best.take(np.array([i]))
        ev = evaluate(winner, cfg, vehicles, progress)
        progress = None                      # the bar counts the first one's evaluation
        if math.isfinite(float(ev.objective[0])):
            return winner, ev
        failed = failed or (winner, ev)
    if failed is None:                       # nothing held in any round either
        winner = best.take(np.array([0]))
        failed = winner, evaluate(winner, cfg, vehicles, progress)
    return failed                            # not finite: tune() says nothing is robust


def tune(cfg: RobustConfig, progress: Callable[[float], None] | None = None,
         pool: Executor | None = None) -> RobustResult:
    """Search the gains for ``cfg.vehicle`` and its ensemble; ``progress(fraction)``. ``pool``:
    :func:`worker_pool`'s processes (``cfg.workers - 1`` of them), else spawned here."""
    rng = np.random.default_rng(cfg.seed)
    period = 1.0 / cfg.rate_hz
    vehicles = ensemble(cfg.vehicle, cfg.neighbours, cfg.spread, period, cfg.seed)
    predict = cfg.predict_delay > 0
    start = predict_seeds(seeds(cfg.vehicle)) if predict else seeds(cfg.vehicle)
    population = Candidates.concat([start, drawn(rng, max(1, cfg.population - len(start)),
                                                   predict)])
    rejected = {"limit cycle": 0, "diverged": 0}
    total = cfg.rounds + 1
    with (contextlib.nullcontext(pool) if pool is not None else workers(cfg.workers)) as pool:
        best, best_obj, evaluated = rounds(cfg, vehicles, population, rng, rejected, total,
                                            progress, pool)
    winner, ev = confirmed(best, best_obj, cfg, vehicles, None if progress is None else (
        lambda f: progress((cfg.rounds + f) / total)))
    fg, pg = candidate_gains(winner, 0, brake_scales(cfg.vehicle), cfg.predict_delay)
    pg = replace(pg, **cfg.law_settings())
    labels = [label for label, _ in cfg.reference_list()]
    if not math.isfinite(float(ev.objective[0])):
        raise RuntimeError("no gain set held on every neighbour: widen the search "
                           "(--population, --rounds) or check the vehicle file")
    return RobustResult(
        TunedGains(fg, pg, rate_hz=cfg.rate_hz, w_c=float(np.mean(cfg.vehicle.w_c)),
                   d_cen=float(np.mean(cfg.vehicle.d_cen)), cost=float(ev.objective[0])),
        objective=float(ev.objective[0]), references=labels,
        nominal_steady_rms=[float(v) for v in ev.steady_rms[0, 0]],
        worst_steady_rms=[float(v) for v in ev.steady_rms[0].max(axis=0)],
        nominal_f_cost=[float(v) for v in ev.f_cost[0, 0]],
        worst_yaw_at_limit=float(ev.yaw_at_limit[0].max()), vehicles=vehicles,
        evaluated=evaluated, rejected=rejected)
