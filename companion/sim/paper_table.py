"""The paper's table computed (:mod:`companion.sim.experiment`): ``pzc_tuned``'s gains when no file
gives them, and the controllers split over worker processes.

``companion paper-table`` (the command: its flags, progress bar and printing) and
``benchmarks/bench_core.py`` (its wall time) both run it from here.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

from ..core.filter import FilterGains
from ..core.pzc import PZCGains
from .experiment import TableConfig, TableResult, merge, run_table

Progress = Callable[[float], None]     # the fraction done, 0..1


def tuned_gains(rate: float, w_c: float, progress: Progress | None = None,
                duration: float = 60.0) -> tuple[FilterGains, PZCGains, str]:
    """(FilterGains, PZCGains, source) for pzc_tuned when no --gains file is given: the shipped
    file for this rate and w_c, else a short tuning run on the spot."""
    from . import gains as gains_mod
    shipped = gains_mod.find_tuned(rate, w_c)
    if shipped is not None:
        return shipped.filter, shipped.pzc, f"shipped {gains_mod.tuned_path(rate, w_c).name}"
    from ..core.limits import Limits
    from .tuning import TuneConfig, tune
    cfg = TuneConfig(rate_hz=rate, w_c=w_c, duration=duration, population=48, rounds=3,
                     limits=Limits())     # the table's plant has no limits; tune for it
    result = tune(cfg, progress)
    return (result.gains.filter, result.gains.pzc,
            f"tuned on the fly (population {cfg.population}, {cfg.rounds} rounds; "
            f"`companion tune --rate {rate:g} --w-c {w_c:g}` searches longer)")


def _worker(config: TableConfig, tuned: tuple[FilterGains, PZCGains], source: str,
            only: tuple[str, ...], shared: Any, conn: Any) -> None:
    """In a worker process: the controllers ``only`` names, sent back over ``conn``; the
    fraction done kept in ``shared`` (a multiprocessing Value)."""
    def progress(frac: float) -> None:
        shared.value = frac
    try:
        conn.send(("ok", run_table(config, tuned, source, progress, only)))
    except BaseException as exc:  # noqa: BLE001  (a worker: reported by the parent, which owns the exit code)
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
    finally:
        conn.close()


def _split(names: tuple[str, ...], jobs: int) -> list[tuple[str, ...]]:
    # pzc + pzc_tuned run as one stacked tracker, so they stay together; roughly equal halves.
    if jobs < 2:
        return [names]
    first = tuple(n for n in names if n in ("pzc", "pzc_tuned"))
    rest = tuple(n for n in names if n not in first)
    return [part for part in (first, rest) if part]


def compute(config: TableConfig, tuned: tuple[FilterGains, PZCGains], source: str, jobs: int,
            progress: Progress | None = None) -> TableResult:
    """Run the table, in ``jobs`` processes when more than one; ``progress`` hears the fraction
    done (in several processes, their mean, every 50 ms)."""
    parts = _split(config.controllers, jobs)
    if len(parts) == 1:
        return run_table(config, tuned, source, progress)
    import multiprocessing as mp
    ctx = mp.get_context("fork" if sys.platform.startswith("linux") else "spawn")
    shared = [ctx.Value("d", 0.0, lock=False) for _ in parts]
    pipes = [ctx.Pipe(duplex=False) for _ in parts]
    # typeshed types get_context(str) as BaseContext, whose subclasses (fork, spawn) have Process
    procs = [ctx.Process(target=_worker,  # type: ignore[attr-defined]
                         args=(config, tuned, source, part, value, send), daemon=True)
             for part, value, (_, send) in zip(parts, shared, pipes, strict=True)]
    try:
        for proc in procs:
            proc.start()
        results: list = [None] * len(parts)
        while any(r is None for r in results):
            for i, (recv, _) in enumerate(pipes):
                if results[i] is None and recv.poll():
                    results[i] = recv.recv()
                elif results[i] is None and not procs[i].is_alive() and not recv.poll():
                    results[i] = ("error", f"worker exited with code {procs[i].exitcode}")
            if progress is not None:
                progress(sum(v.value for v in shared) / len(shared))
            time.sleep(0.05)
    finally:
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
            proc.join()
    errors = [msg for kind, msg in results if kind == "error"]
    if errors:
        raise RuntimeError("paper-table worker failed: " + "; ".join(errors))
    return merge([table for _, table in results])
