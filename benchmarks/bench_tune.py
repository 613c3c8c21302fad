"""Benchmark of the robust tuner's simulation: the plant step compiled against numpy, side by side.

    python benchmarks/bench_tune.py                       the bundled skid-steer and car files
    python benchmarks/bench_tune.py --vehicle FILE ...    any vehicle files (a PX4 calibrate's)
    python benchmarks/bench_tune.py --tune                and calibrate's final search, timed

Prints, per vehicle file, in one run with the two interleaved (the machine is shared and its
speed moves 20-30 % between minutes):
  * the plant step (RoverModel.step / step_vector) per vehicle at 1,344 vehicles (64 candidates
    on 7 neighbours and 3 references: one process's share of calibrate's final search), in ns;
  * one robust evaluation of those 64 candidates (robust.evaluation.evaluate, one process), in s, and
    whether the two gave the same objective for every candidate;
  * ``--tune``: calibrate's final search (128 x 4, its worker count) with the compiled step.
Asserts nothing.
"""

from __future__ import annotations

import argparse
import statistics
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from companion.app.vehicle import load, tuner_config
from companion.sim import plant_lanes
from companion.sim.plant import RoverState
from companion.sim.robust import candidates, config, ensemble, evaluation, search
from companion.sim.vehicle_gains import FINAL_SEARCH, tune_workers

ROOT = Path(__file__).resolve().parent.parent
VEHICLES = [ROOT / "companion/sim/vehicles/ardupilot_skid.toml",
            ROOT / "benchmarks/vehicles/ardupilot_car_sitl.toml"]


@contextmanager
def plant(compiled: bool):
    """The compiled step, or numpy's (as where numba is not installed)."""
    saved = plant_lanes._compiled
    if not compiled:
        plant_lanes._compiled = None
    try:
        yield
    finally:
        plant_lanes._compiled = saved


def step_ns(cfg: config.RobustConfig, n: int, steps: int = 1000) -> float:
    """ns per vehicle per plant step on the ensemble's parameters, moving commands."""
    vehicles = ensemble.ensemble(cfg.vehicle, cfg.neighbours, cfg.spread, 1 / cfg.rate_hz,
                                 cfg.seed)
    params = ensemble.stack_params(vehicles, 1, -(-n // len(vehicles)))
    n = len(np.atleast_1d(params.w_c))
    model = plant_lanes.batch_model(params, n)
    zero = np.zeros(n)
    s = RoverState(zero, zero, zero, zero, zero)
    phase = np.random.default_rng(0).uniform(0, 10, n)
    vector = params.velocity_vector
    t0 = time.perf_counter()
    for k in range(steps):
        a = 1.5 + np.sin(0.02 * k + phase)
        b = np.cos(0.03 * k + phase)
        s = model.step_vector(s, a, b, 0.02) if vector else model.step(s, a, b, 0.02)
    return (time.perf_counter() - t0) / steps / n * 1e9


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicle", nargs="+", type=Path, default=VEHICLES)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tune", action="store_true", help="time calibrate's final search too")
    args = ap.parse_args()
    print(f"numba compiled the plant step: {plant_lanes.available()}")
    for path in args.vehicle:
        cfg = tuner_config(load(path), 40.0, (), **FINAL_SEARCH)
        vehicles = ensemble.ensemble(cfg.vehicle, cfg.neighbours, cfg.spread, 1 / cfg.rate_hz,
                                     cfg.seed)
        refs = len(cfg.reference_list())
        rng = np.random.default_rng(1)
        start = candidates.seeds(cfg.vehicle)
        cands = candidates.Candidates.concat([start, candidates.drawn(rng, 64 - len(start))])
        lanes = 64 * len(vehicles) * refs
        with plant(True):                      # compile (or load numba's cache) outside the timing
            step_ns(cfg, 64, steps=5)
        times: dict[bool, list[float]] = {True: [], False: []}
        steps: dict[bool, list[float]] = {True: [], False: []}
        objective: dict[bool, np.ndarray] = {}
        for _ in range(args.repeats):
            for compiled in (True, False):
                with plant(compiled):
                    steps[compiled].append(step_ns(cfg, lanes))
                    t0 = time.perf_counter()
                    objective[compiled] = evaluation.evaluate(cands, cfg, vehicles).objective
                    times[compiled].append(time.perf_counter() - t0)
        same = np.array_equal(objective[True], objective[False])
        print(f"\n{path.name}: {len(vehicles)} vehicles x {refs} references x 64 candidates "
              f"= {lanes} lanes")
        for compiled, label in ((True, "compiled"), (False, "numpy   ")):
            print(f"  {label}  plant step {statistics.median(steps[compiled]):6.0f} ns/vehicle"
                  f"   evaluation {statistics.median(times[compiled]):5.2f} s "
                  f"(min {min(times[compiled]):.2f}, max {max(times[compiled]):.2f})")
        print(f"  evaluation: numpy / compiled = "
              f"{statistics.median(times[False]) / statistics.median(times[True]):.2f}; "
              f"same objective for all 64: {same}")
        if args.tune:
            cfg = tuner_config(load(path), 40.0, (), **FINAL_SEARCH, workers=tune_workers())
            t0 = time.perf_counter()
            result = search.tune(cfg)
            print(f"  calibrate's final search {FINAL_SEARCH['population']} x "
                  f"{FINAL_SEARCH['rounds']} on {tune_workers()} processes: "
                  f"{time.perf_counter() - t0:.1f} s (objective {result.objective:.4f})")


if __name__ == "__main__":
    main()
