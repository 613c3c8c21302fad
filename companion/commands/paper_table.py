"""``companion paper-table``: the paper's Figure 13 reproduced (Section 5), with two more controllers.

Six scenarios x four controllers (paper-gain PZC, tuned PZC, the paper's PID, Kanayama) in batch
simulation; see :mod:`companion.sim.experiment` for the set-up and what the paper leaves unsaid.
The controllers are split over up to two worker processes (``--jobs``), one per core here
(:mod:`companion.sim.paper_table` computes it; this module reads the flags and prints).

``pzc_tuned`` gains, first found wins: ``--gains FILE``; the shipped file for this rate and w_c
(``companion/sim/tuned/``); else a short tuning run on the spot. The JSON says which
(``pzc_tuned_source``).
"""

from __future__ import annotations

import json
import os
import sys
import time

from ..errors import UserError, require_positive


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "paper-table", help="reproduce the paper's Figure 13 cost table (and Figures 4-12)",
        description="Simulate the paper's six Section 5 scenarios with PZC (paper gains), PZC "
                    "(tuned gains), the paper's PID and Kanayama's law; print f_cost and steady RMS.")
    p.add_argument("--rate", type=float, default=1000.0, metavar="HZ",
                   help="controller rate (default 1000, the paper's)")
    p.add_argument("--w-c", type=float, default=20.0, dest="w_c", metavar="RAD_S",
                   help="actuator bandwidth w_c of the simulated rover (default 20)")
    p.add_argument("--duration", type=float, default=60.0, metavar="S",
                   help="simulated seconds per scenario (default 60)")
    p.add_argument("--gains", metavar="FILE", help="tuned-gains file for pzc_tuned")
    p.add_argument("--literal", action="store_true",
                   help="also run the paper's literal speed law v_ref = |u_p| (pzc_literal)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", metavar="DIR", help="write the paper's Figures 4-13 as PNG files")
    p.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), metavar="N",
                   help="worker processes (default: up to 2)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _check(args) -> None:
    for flag, value in (("--rate", args.rate), ("--w-c", args.w_c), ("--duration", args.duration)):
        require_positive(flag, value)
    if args.rate > 10000:
        raise UserError(f"--rate must be at most 10000 Hz, not {args.rate!r}")
    if args.jobs < 1:
        raise UserError(f"--jobs must be at least 1, not {args.jobs!r}")


def _advance(bar, percent: float) -> None:
    # update() honours tqdm's mininterval, so a fast caller does not flood the terminal.
    if bar is not None and percent > bar.n:
        bar.update(round(percent - bar.n, 1))


def _print_table(result) -> None:
    d = result.as_dict()
    names = list(d["average"])
    print(f"paper-table: {d['rate_hz']:g} Hz controller, w_c {d['w_c']:g} rad/s, "
          f"{d['duration_s']:g} s per run; start at the origin at rest heading +x")
    print(f"pzc_tuned gains: {d['pzc_tuned_source']}")
    print("f_cost (steady RMS m)")
    print(f"{'f_r Hz':>7} {'d_cen m':>8} " + " ".join(f"{n:>18}" for n in names))
    for s in d["scenarios"]:
        cells = [_cell(s["controllers"][n]) for n in names]
        print(f"{s['f_r']:7.2f} {s['d_cen']:8.1f} " + " ".join(f"{c:>18}" for c in cells))
    averages = ["diverged" if _any_diverged(d, n) else f"{d['average'][n]:.3f}" for n in names]
    print(f"{'average':>16} " + " ".join(f"{a:>18}" for a in averages))
    pzc = ("diverged" if _any_diverged(d, "pzc") else f"{100 * d['improvement_vs_pid']:.1f} %")
    tuned = ("diverged" if _any_diverged(d, "pzc_tuned")
             else f"{100 * d['improvement_vs_pid_tuned']:.1f} %")
    print(f"improvement vs PID (average f_cost): pzc {pzc}, pzc_tuned {tuned} (paper: 37 %)")
    if not _any_diverged(d, "pzc"):
        print(f"pzc f_cost spread over the scenarios (max/min): {d['pzc_cost_spread']:.2f}")


def _any_diverged(d: dict, name: str) -> bool:
    return any(s["controllers"][name]["diverged"] for s in d["scenarios"])


def _cell(c: dict) -> str:
    if c["diverged"]:
        return "diverged"
    return f"{c['f_cost']:8.3f} ({c['steady_rms']:6.3f})"


def run(args) -> int:
    _check(args)
    from ..sim.experiment import TableConfig
    from ..sim.paper_table import compute, tuned_gains

    # A gains file is read (and any mistake in it reported) before anything else starts.
    preset = None
    if args.gains:
        from ..sim import gains as gains_mod
        g = gains_mod.load(args.gains)
        preset = (g.filter, g.pzc, f"file {args.gains}")
    bar = None
    if not args.no_progress:
        from tqdm import tqdm
        bar = tqdm(total=100, desc="paper-table", file=sys.stderr,
                   bar_format="{desc} {percentage:3.0f}%|{bar}| {elapsed}<{remaining}",
                   mininterval=0.5)
    try:
        def tune_progress(frac):
            if bar is not None:
                bar.set_description_str("tuning pzc_tuned", refresh=False)
            _advance(bar, 100 * frac)
        fg, pg, source = preset or tuned_gains(args.rate, args.w_c, tune_progress,
                                               args.duration)
        if bar is not None:
            bar.set_description_str("paper-table", refresh=False)
            bar.reset()
        config = TableConfig(rate_hz=args.rate, w_c=args.w_c, duration=args.duration,
                             with_literal=args.literal,
                             trace_every=0.02 if args.plot else None)
        started = time.perf_counter()
        result = compute(config, (fg, pg), source, args.jobs,
                         lambda frac: _advance(bar, 100 * frac))
        wall = time.perf_counter() - started
    finally:
        if bar is not None:
            bar.close()

    files = []
    if args.plot:
        from ..sim.paper_plots import plot_all
        files = plot_all(result, args.plot)
    if args.json:
        out = result.as_dict()
        out["wall_time_s"] = round(wall, 3)
        if files:
            out["plots"] = [str(f) for f in files]
        print(json.dumps(out))
    else:
        _print_table(result)
        print(f"simulated in {wall:.1f} s")
        if files:
            print(f"figures: {len(files)} PNG files in {args.plot}")
    return 0
