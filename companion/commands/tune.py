"""``companion tune``: search filter and PZC gains for a loop rate, actuator and limits.

With ``--vehicle FILE`` (a vehicle file from ``companion identify``) the search is robust
(:func:`companion.sim.robust.search.tune`): the identified inner loops and an ensemble of neighbours, the
autopilot's telemetry timing, the missions given (``--mission``, repeatable) or the paper's
ellipse at four speeds; a gain set whose worst neighbour limit-cycles is rejected. The gains file
records the vehicle file (name and SHA-256), the ensemble and the command line.

The search is :func:`companion.sim.tuning.tune` (batch simulation of a population of gain sets on the
paper's ellipse at several reference speeds at once). The result prints as a table, or as JSON
with ``--json``, and ``--out FILE`` writes a tuned-gains file that ``companion run``, ``demo``,
``simulate`` and ``paper-table`` read (``--gains FILE``). Files named
``companion/sim/tuned/rate<HZ>_wc<W_C>.toml`` are picked up automatically for that rate and w_c.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import UserError, require_positive
from ..progress import progress_bar

if TYPE_CHECKING:   # a hint only: the command loads numpy when it runs, not to build the CLI
    from ..core.trajectory import Trajectory


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "tune", help="search the filter and PZC gains for a loop rate and actuator",
        description="Search k_df, lambda_f, k_dc, lambda_c (and the optional yaw pair and "
                    "feed-forward extensions) by batch simulation for the lowest mean f_cost "
                    "over several reference speeds.")
    p.add_argument("--rate", type=float, metavar="HZ",
                   help="controller rate (required without --vehicle; with it, default 40)")
    p.add_argument("--vehicle", metavar="FILE",
                   help="tune robustly for this identified vehicle (companion identify)")
    p.add_argument("--mission", action="append", default=[], metavar="FILE",
                   help="with --vehicle: tune on this mission's trajectory (repeatable; "
                        "default the paper's ellipse at those of 0.02, 0.04, 0.08, 0.12 Hz the "
                        "vehicle can turn through, and for a car accelerate along)")
    p.add_argument("--neighbours", type=int, default=6, metavar="N",
                   help="with --vehicle: perturbed neighbours besides the vehicle (default 6)")
    # (None: not given. With --vehicle the plant and its limits are the vehicle file's, so the
    # flags that describe them are refused there rather than silently ignored.)
    p.add_argument("--w-c", type=float, dest="w_c", metavar="RAD_S",
                   help="actuator bandwidth of the rover (default 20; a stock rover is about 1.2)")
    p.add_argument("--d-cen", type=float, dest="d_cen", metavar="M",
                   help="distance from the tracked point to the wheel axle (default 0)")
    p.add_argument("--f-r", metavar="HZ,HZ,...",
                   help="reference frequencies of the paper's ellipse to tune over together "
                        "(default 0.04,0.08,0.12; with --vehicle, in place of --mission)")
    p.add_argument("--duration", type=float, metavar="S",
                   help="simulated seconds per run (default 60; with --vehicle and --mission, "
                        "the longest mission's, at most 120)")
    p.add_argument("--max-speed", type=float, metavar="M_S",
                   help="command speed limit (default: the companion's, as run resolves it)")
    p.add_argument("--max-yaw-rate", type=float, metavar="RAD_S",
                   help="command yaw-rate limit (default: the companion's, as run resolves it)")
    p.add_argument("--max-accel", type=float, metavar="M_S2",
                   help="the rover's acceleration limit (default none)")
    p.add_argument("--population", type=int, metavar="N",
                   help="gain sets simulated per round (default 128; with --vehicle the "
                        "robust tuner's)")
    p.add_argument("--rounds", type=int, metavar="N",
                   help="search rounds (default 4; with --vehicle the robust tuner's)")
    p.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    p.add_argument("--out", metavar="FILE", help="write the gains to this TOML file")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _frequencies(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"--f-r must be comma-separated frequencies in Hz, not {text!r}") from None
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise UserError(f"--f-r frequencies must be > 0, not {text!r}")
    return values


LINEAR_DEFAULTS = {"w_c": 20.0, "d_cen": 0.0, "f_r": "0.04,0.08,0.12", "duration": 60.0,
                   "max_accel": math.inf}
# What describes the plant or its limits: the vehicle file's own with --vehicle.
PLANT_FLAGS = {"w_c": "--w-c", "d_cen": "--d-cen", "max_accel": "--max-accel",
               "max_speed": "--max-speed", "max_yaw_rate": "--max-yaw-rate"}


def check(args) -> tuple[float, ...]:
    for name, value in LINEAR_DEFAULTS.items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    for flag, value in (("--rate", args.rate), ("--w-c", args.w_c), ("--duration", args.duration),
                        ("--max-speed", args.max_speed), ("--max-yaw-rate", args.max_yaw_rate)):
        require_positive(flag, value)
    if args.rate > 10000:
        raise UserError(f"--rate must be at most 10000 Hz, not {args.rate!r}")
    if not (math.isfinite(args.d_cen) and args.d_cen >= 0):
        raise UserError(f"--d-cen must be a distance >= 0, not {args.d_cen!r}")
    if not args.max_accel > 0:
        raise UserError(f"--max-accel must be > 0, not {args.max_accel!r}")
    if args.population < 8:
        raise UserError(f"--population must be at least 8, not {args.population}")
    if args.rounds < 1:
        raise UserError(f"--rounds must be at least 1, not {args.rounds}")
    if args.out:
        parent = Path(args.out).resolve().parent
        if not parent.is_dir():
            raise UserError(f"--out {args.out}: directory {parent} does not exist")
    return _frequencies(args.f_r)


def _save(gains, d: dict, args) -> bool:
    """Write ``--out``; with ``--json`` print ``d`` (plus "out") and say the report is done."""
    if args.out:
        gains.save(args.out)
    if not args.json:
        return False
    if args.out:
        d["out"] = args.out
    print(json.dumps(d))
    return True


def _describe(result) -> dict:
    return {**_describe_gains(result.gains),
            "f_r": list(result.f_r),
            "f_cost": result.cost_per_reference,
            "steady_rms": result.steady_rms_per_reference,
            "evaluated": result.evaluated}


def _describe_gains(g) -> dict:
    pzc = g.pzc
    return {
        "rate_hz": g.rate_hz, "w_c": g.w_c, "d_cen": g.d_cen,
        "filter": {"k_df": float(g.filter.k_df), "lambda_f": float(g.filter.lambda_f)},
        "pzc": {"k_dc": float(pzc.k_dc), "lambda_c": float(pzc.lambda_c),
                "k_dc_yaw": None if pzc.k_dc_yaw is None else float(pzc.k_dc_yaw),
                "lambda_c_yaw": None if pzc.lambda_c_yaw is None else float(pzc.lambda_c_yaw),
                "velocity_ff": bool(pzc.velocity_ff), "heading_rate_ff": bool(pzc.heading_rate_ff),
                "accel_ff": float(pzc.accel_ff),
                "lead_tau": float(pzc.lead_tau), "lead_max_gain": float(pzc.lead_max_gain),
                "speed_law": pzc.speed_law,
                "accel_ff_turn": None if pzc.accel_ff_turn is None else float(pzc.accel_ff_turn),
                "brake_accel": float(pzc.brake_accel),
                "brake_yaw_accel": float(pzc.brake_yaw_accel)},
        "cost": g.cost,
    }


def run(args) -> int:
    if args.vehicle:
        return run_robust(args)
    if args.mission:
        raise UserError("--mission needs --vehicle (the linear tuner uses the paper's ellipse)")
    if args.rate is None:
        raise UserError("--rate is required (or --vehicle FILE for a robust tune)")
    args.population = 128 if args.population is None else args.population
    args.rounds = 4 if args.rounds is None else args.rounds
    f_r = check(args)
    from ..live import policy
    from ..sim.tuning import TuneConfig, tune

    # The limits a run without a mission's or vehicle's would fly (the one policy).
    limits = policy.choose_limits(None, policy.GainOptions(max_speed=args.max_speed,
                                                          max_yaw_rate=args.max_yaw_rate))
    cfg = TuneConfig(rate_hz=args.rate, w_c=args.w_c, d_cen=args.d_cen, f_r=f_r,
                     duration=args.duration, limits=limits,
                     max_accel=args.max_accel, population=args.population, rounds=args.rounds,
                     seed=args.seed)
    with progress_bar(f"tune {args.rate:g} Hz", not args.no_progress) as progress:
        result = tune(cfg, progress)
    d = _describe(result)
    if _save(result.gains, d, args):
        return 0
    print(f"tuned for {args.rate:g} Hz, w_c {args.w_c:g} rad/s, d_cen {args.d_cen:g} m, "
          f"limits {cfg.limits.max_speed:g} m/s, {cfg.limits.max_yaw_rate:g} rad/s "
          f"({result.evaluated} gain sets simulated)")
    _print_gains(d)
    for fr, cost, rms in zip(d["f_r"], d["f_cost"], d["steady_rms"], strict=True):
        print(f"  f_r {fr:5.2f} Hz: f_cost {cost:7.3f}  steady RMS {rms:6.3f} m")
    print(f"cost (mean f_cost) {d['cost']:.4f}")
    if args.out:
        print(f"written to {args.out}")
    return 0


def _print_gains(d: dict) -> None:
    p = d["pzc"]
    print(f"filter  k_df {d['filter']['k_df']:.4g}  lambda_f {d['filter']['lambda_f']:.4g}")
    yaw = ("same as position" if p["k_dc_yaw"] is None
           else f"k_dc_yaw {p['k_dc_yaw']:.4g}  lambda_c_yaw {p['lambda_c_yaw']:.4g}")
    print(f"pzc     k_dc {p['k_dc']:.4g}  lambda_c {p['lambda_c']:.4g}  yaw: {yaw}")
    print(f"        velocity_ff {p['velocity_ff']}  heading_rate_ff {p['heading_rate_ff']}  "
          f"accel_ff {p['accel_ff']:.3g} s  speed_law {p['speed_law']}")
    print("        actuator lead: " + ("off" if p["lead_tau"] == 0 else
                                        f"tau {p['lead_tau']:.3g} s, max gain {p['lead_max_gain']:.3g}"))
    turn = "as accel_ff" if p["accel_ff_turn"] is None else f"{p['accel_ff_turn']:.3g} s"
    brakes = ", ".join(f"{name} {p[key]:.3g} {unit}" for name, key, unit in (
        ("position", "brake_accel", "m/s^2"), ("yaw", "brake_yaw_accel", "rad/s^2")) if p[key])
    print(f"        turning preview {turn}; braking curves: {brakes or 'off'}")


def mission_references(paths: list[str]) -> tuple[list[tuple[str, Trajectory]], float]:
    """Missions as the robust tuner's references (``start`` frame at the simulated rover's
    pose; other frames moved so the path begins there) and the duration to simulate."""
    from .. import mission as missions_mod
    from ..mission.paths import Placed
    refs: list[tuple[str, Trajectory]] = []
    durations: list[float] = []
    for path in paths:
        m = missions_mod.load(path)
        traj = m.trajectory
        if m.frame != "start":
            first = traj.sample(0.0)
            traj = Placed(traj, -float(first.x), -float(first.y), 0.0)
        refs.append((m.name or path, traj))
        durations.append(min(m.duration, 120.0))
    return refs, (max(durations) if durations else 60.0)


def run_robust(args) -> int:
    from ..sim.robust.config import RobustConfig
    from ..sim.robust.search import tune as robust_tune
    args.population = RobustConfig.population if args.population is None else args.population
    args.rounds = RobustConfig.rounds if args.rounds is None else args.rounds
    rate = 40.0 if args.rate is None else args.rate
    require_positive("--rate", rate)
    for name, flag in PLANT_FLAGS.items():
        if getattr(args, name) is not None:
            raise UserError(f"{flag} describes the rover, which --vehicle {args.vehicle} "
                            f"already does (its model and limits): leave {flag} out")
    if args.population < 8:
        raise UserError(f"--population must be at least 8, not {args.population}")
    if args.rounds < 1:
        raise UserError(f"--rounds must be at least 1, not {args.rounds}")
    if not 0 <= args.neighbours <= 64:
        raise UserError(f"--neighbours must be 0..64, not {args.neighbours}")
    if args.out and not Path(args.out).resolve().parent.is_dir():
        raise UserError(f"--out {args.out}: directory {Path(args.out).resolve().parent} does not exist")
    from ..app.vehicle import load as load_vehicle
    from ..app.vehicle import tuner_config
    from ..core.trajectory import Ellipse
    from ..sim.vehicle_gains import record
    refs, duration = mission_references(args.mission)
    if args.f_r is not None:
        if args.mission:
            raise UserError("--f-r and --mission both name the references: give one")
        refs = [(f"ellipse {f:g} Hz", Ellipse.paper(f)) for f in _frequencies(args.f_r)]
    if args.duration is not None:
        require_positive("--duration", args.duration)
        duration = args.duration
    vehicle = load_vehicle(args.vehicle)           # read once
    cfg = tuner_config(vehicle, rate, refs, duration, population=args.population,
                       rounds=args.rounds, neighbours=args.neighbours, seed=args.seed)
    with progress_bar(f"robust tune {rate:g} Hz", not args.no_progress) as progress:
        try:
            result = robust_tune(cfg, progress)
        except RuntimeError as exc:
            raise UserError(str(exc)) from None
    command = "companion tune " + " ".join(sys.argv[2:]) if sys.argv[1:2] == ["tune"] else \
        f"companion tune --vehicle {args.vehicle}"
    gains = record(result, cfg, args.vehicle, vehicle.sha256, command)
    d = {**_describe_gains(gains), "vehicle": args.vehicle, "references": result.references,
         "steady_rms": result.nominal_steady_rms, "worst_steady_rms": result.worst_steady_rms,
         "f_cost": result.nominal_f_cost, "worst_yaw_at_limit": result.worst_yaw_at_limit,
         "ensemble": len(result.vehicles), "evaluated": result.evaluated,
         "rejected": result.rejected}
    if _save(gains, d, args):
        return 0
    print(f"robust tune for {args.vehicle} at {rate:g} Hz: the vehicle and "
          f"{len(result.vehicles) - 1} neighbours, {result.evaluated} gain sets simulated "
          f"({result.rejected['limit cycle']} limit-cycled, {result.rejected['diverged']} diverged)")
    _print_gains(d)
    for label, a, b, c in zip(result.references, result.nominal_steady_rms,
                              result.worst_steady_rms, result.nominal_f_cost, strict=True):
        print(f"  {label:24s} steady RMS {a:6.3f} m (worst neighbour {b:6.3f})  f_cost {c:7.3f}")
    if args.out:
        print(f"written to {args.out}")
    return 0
