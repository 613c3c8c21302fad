"""Benchmark of the control core: one controller step, batch throughput, the paper table.

    python benchmarks/bench_core.py            (or: make bench)
    python benchmarks/bench_core.py --quick    (shorter runs, for a smoke check)

Prints, side by side in one run:
  * one controller step (filter + PZC law, one vehicle, plain Python floats) in microseconds:
    median over blocks of steps (target: at most 5 us), with the baselines for comparison;
  * batch simulation throughput in vehicle-steps per second (one vehicle advanced by one 1 ms
    plant step, control included) at 1, 100 and 10,000 vehicles, at 1 kHz and at 40 Hz control
    (target: at least 5 million at 10,000 vehicles);
  * the wall time of the whole 1 kHz paper table, four controllers, one and two processes
    (target: under 15 s).
The machine is shared and noisy: figures are medians of repeats, and the spread is printed.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

from companion.core.baselines import KanayamaGains, KanayamaTracker, PIDGains, PIDTracker
from companion.core.filter import FilterGains
from companion.core.limits import Limits
from companion.core.pzc import PZCGains, PZCTracker
from companion.core.trajectory import Ellipse
from companion.sim.batch import SimConfig, simulate
from companion.sim.plant import RoverModel, RoverParams, RoverState


def step_time_us(tracker, blocks: int, per_block: int = 2000) -> tuple[float, float, float]:
    """Median, min and max of the mean step time over blocks, in microseconds."""
    ref_traj = Ellipse.paper(0.12)
    model = RoverModel(RoverParams.paper())
    state = RoverState()
    # Pre-compute inputs so the timing is the tracker alone.
    refs = [ref_traj.sample(k * 1e-3) for k in range(per_block)]
    meas = []
    for _ in range(per_block):
        meas.append(model.measure(state))
        state = model.step(state, 1.0, 0.2, 1e-3)
    tracker.reset()
    t0 = 0.0
    means = []
    for _ in range(blocks):
        step = tracker.step
        start = time.perf_counter_ns()
        for k in range(per_block):
            step(t0 + k * 1e-3, meas[k], refs[k])
        means.append((time.perf_counter_ns() - start) / per_block / 1000.0)
        t0 += per_block * 1e-3
    return statistics.median(means), min(means), max(means)


def throughput(n: int, rate: float, duration: float, repeats: int) -> tuple[float, float]:
    """Vehicle-steps (1 ms plant steps) per second, median and best over repeats."""
    rng = np.random.default_rng(0)
    f_r = rng.choice([0.04, 0.08, 0.12], n)
    d_cen = rng.choice([0.0, 0.3, 0.6], n)
    gains = PZCGains(velocity_ff=True, heading_rate_ff=True)
    config = SimConfig(duration=duration, control_rate=rate)
    plant_steps = round(duration * rate) * config.substeps
    rates = []
    for _ in range(repeats):
        tracker = PZCTracker(FilterGains(), gains, Limits(6.0, 6.0), n=n)
        params = RoverParams(d_cen=d_cen, w_c=20.0)
        start = time.perf_counter()
        simulate(tracker, params, Ellipse.paper(f_r), n, config)
        rates.append(n * plant_steps / (time.perf_counter() - start))
    return statistics.median(rates), max(rates)


ARDUPILOT_LIKE = dict(w_c=1 / 0.3, w_c_yaw=1 / 0.05, max_speed=4.0, max_yaw_rate=2.0944,
                      max_accel=1.0, max_yaw_accel=2.0944, speed_delay=0.05, yaw_delay=0.04,
                      turn_speed_coupling=0.3)


def vehicle_seconds(n: int, full: bool, plant_dt: float, duration: float) -> float:
    """Simulated vehicle-seconds per wall second at 40 Hz control (the robust tuner's unit)."""
    rng = np.random.default_rng(0)
    f_r = rng.choice([0.04, 0.08, 0.12], n)
    gains = PZCGains(0.3, 0.6, k_dc_yaw=1.5, lambda_c_yaw=1.5, velocity_ff=True,
                     heading_rate_ff=True)
    if full:   # every vehicle a neighbour of its own: per-vehicle limits and delays
        params = RoverParams(**{**ARDUPILOT_LIKE, "max_accel": rng.uniform(0.7, 1.3, n),
                                "speed_delay": rng.choice([0.025, 0.05, 0.075], n)})
        config = SimConfig(duration=duration, control_rate=40.0, max_plant_dt=plant_dt, tick=0.02)
    else:
        params = RoverParams(w_c=20.0)
        config = SimConfig(duration=duration, control_rate=40.0, max_plant_dt=plant_dt)
    tracker = PZCTracker(FilterGains(1000.0, 40.0), gains, Limits(4.0, 2.0944), n=n)
    start = time.perf_counter()
    simulate(tracker, params, Ellipse.paper(f_r), n, config)
    return n * duration / (time.perf_counter() - start)


def paper_table_wall(jobs: int) -> float:
    from companion.sim.experiment import TableConfig
    from companion.sim.paper_table import compute, tuned_gains
    fg, pg, source = tuned_gains(1000.0, 20.0)
    start = time.perf_counter()
    compute(TableConfig(rate_hz=1000.0, w_c=20.0), (fg, pg), source, jobs)
    return time.perf_counter() - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs")
    args = parser.parse_args()
    quick = args.quick
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.2f}")

    print("\none controller step, one vehicle, plain Python (median [min-max] of block means)")
    blocks = 5 if quick else 25
    rows = [
        ("filter + PZC (paper form)", PZCTracker(FilterGains(), PZCGains(), Limits(6.0, 6.0))),
        ("filter + PZC + feed-forwards", PZCTracker(FilterGains(), PZCGains(
            velocity_ff=True, heading_rate_ff=True), Limits(6.0, 6.0))),
        ("filter + PZC + actuator lead", PZCTracker(FilterGains(), PZCGains(
            lead_tau=0.8, lead_max_gain=8.0), Limits(6.0, 6.0))),
        ("PID baseline", PIDTracker(PIDGains(), Limits(6.0, 6.0))),
        ("Kanayama baseline", KanayamaTracker(KanayamaGains(), Limits(6.0, 6.0))),
    ]
    for label, tracker in rows:
        med, lo, hi = step_time_us(tracker, blocks)
        target = "  (target <= 5 us)" if label.startswith("filter + PZC (paper") else ""
        print(f"  {label:32s} {med:6.2f} us  [{lo:.2f}-{hi:.2f}]{target}")

    print("\nbatch simulation throughput, PZC, vehicle-steps per second (1 ms plant steps)")
    cases = [(1, 1000.0, 2.0), (100, 1000.0, 2.0), (10000, 1000.0, 1.0),
             (1, 40.0, 10.0), (100, 40.0, 10.0), (10000, 40.0, 5.0)]
    if quick:
        cases = [(n, r, d / 4) for n, r, d in cases]
    for n, rate, duration in cases:
        med, best = throughput(n, rate, duration, repeats=1 if quick else 3)
        target = "  (target >= 5 M at 10,000)" if n == 10000 else ""
        print(f"  {n:6d} vehicles at {rate:6g} Hz control: {med / 1e6:7.3f} M/s median, "
              f"{best / 1e6:7.3f} M/s best{target}")

    print("\nbatch throughput at 40 Hz control, 10,000 vehicles, simulated vehicle-seconds per "
          "wall second")
    duration = 2.0 if quick else 6.0
    for label, full, dt in (("linear plant, 1 ms steps (the paper's)", False, 1e-3),
                            ("full vehicle model, 1 ms steps", True, 1e-3),
                            ("full vehicle model, 10 ms steps", True, 1e-2),
                            ("full vehicle model, 20 ms steps (the tuner's)", True, 2e-2)):
        rate = vehicle_seconds(10000, full, dt, duration)
        target = "  (target >= 50,000)" if "tuner" in label else ""
        print(f"  {label:46s} {rate:9,.0f}{target}")

    if not quick:
        print("\nwhole 1 kHz paper table (6 scenarios x 4 controllers, 60 s each)")
        for jobs in (1, 2):
            print(f"  {jobs} process{'es' if jobs > 1 else ''}: {paper_table_wall(jobs):6.2f} s"
                  f"{'  (target < 15 s)' if jobs == 2 else ''}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
