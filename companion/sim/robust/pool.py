"""The worker processes that share an evaluation's candidates: spawned, warmed ahead if asked,
deaf to Ctrl-C (the parent's to act on)."""

from __future__ import annotations

import contextlib
import multiprocessing
import signal
from collections.abc import Iterator
from concurrent.futures import Executor, ProcessPoolExecutor

import numpy as np

from ..plant import RoverParams, RoverState
from ..plant_lanes import batch_model


def _worker_start() -> None:
    """Each spawned process first: Ctrl-C is the parent's to act on (it stops the search and
    shuts the pool down), not a traceback from every worker."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _warm() -> None:
    """A worker's first task when the pool is started ahead (:func:`worker_pool`): the
    evaluation its tasks run is imported, and one step loads the compiled plant (numba's cache)."""
    from . import evaluation  # noqa: F401  (imported now, while the worker waits, not in round one)
    model = batch_model(RoverParams.stock_rover(), 2)
    model.step(RoverState(np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2)),
               0.0, 0.0, 0.02)


@contextlib.contextmanager
def workers(count: int) -> Iterator[Executor | None]:
    """``count - 1`` spawned processes for :func:`evaluate` (None for one: this process
    alone). Spawned, not forked: the caller may have threads (a link, a progress bar)."""
    if count <= 1:
        yield None
        return
    with ProcessPoolExecutor(count - 1, mp_context=multiprocessing.get_context("spawn"),
                             initializer=_worker_start) as pool:
        yield pool


@contextlib.contextmanager
def worker_pool(count: int) -> Iterator[Executor | None]:
    """:func:`~companion.sim.robust.search.tune`'s processes started now and warmed (Python,
    numpy, the evaluation and the compiled plant loaded: seconds each) while the caller does
    other work, for ``tune(cfg, pool=...)`` with ``cfg.workers == count`` (calibrate: during its
    refining tune and flight). Idle, a worker only waits."""
    with workers(count) as pool:
        if pool is not None:
            for _ in range(count - 1):
                pool.submit(_warm)
        yield pool
