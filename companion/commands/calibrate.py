"""``companion calibrate``: one command for a new rover, identify it live, then tune for it.

    companion calibrate --connect URL --out DIR [--arm] [--space R] [identify's flags]

1. flies ``companion identify``'s excitation manoeuvre (within ``--space`` metres, at most 90 s,
   every failsafe of ``run``) and fits the vehicle model: ``DIR/vehicle.toml``;
2. refines: tunes quick gains for the refining flight only (a 32 x 1 robust search, a few
   seconds), flies the paper's ellipse at 0.08 Hz (shrunk to ``--space``) for 30 s with them,
   fits one model to the manoeuvre and that track together, and keeps it when it explains both
   flights within 0.15 m/s and 0.15 rad/s and predicts the track better than the manoeuvre's
   model did. Why: on ArduPilot SITL the manoeuvre alone reads the speed loop's delay long
   (0.22 s against 0.15 s from tracking: its speed steps start from rest) and its gains track
   the 0.08 Hz ellipse less well, while a model fitted to tracking alone misreads what tracking
   does not exercise (the turn/speed coupling) and mispredicts a faster track; the joint fit
   predicted held-out tracks at every speed as well as or better than either (``--no-refine``
   skips this step; it needs the flight logs);
3. tunes gains for the model kept, on it and its neighbours (``companion tune --vehicle``,
   128 x 4 unless ``--population`` / ``--rounds`` say otherwise, each round's candidates split
   over the machine's cores, the other processes started and warmed during step 2: the same
   gains as in one process): ``DIR/gains.toml``, recorded
   with the vehicle file's SHA-256;
4. prints the ``companion run --vehicle DIR/vehicle.toml`` command that flies with them.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from dataclasses import replace
from pathlib import Path

from ..errors import ExitCode, UserError
from .identify import EPILOG, add_live_arguments


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "calibrate", help="identify a rover live and tune gains for it (vehicle.toml, gains.toml)",
        description=__doc__.split("\n\n", 1)[1], epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder for vehicle.toml and gains.toml (created if missing)")
    t = p.add_argument_group("tuning")
    # (defaults resolved when calibrate runs: the tuner's module is not imported to build the CLI)
    t.add_argument("--population", type=int, metavar="N",
                   help="gain sets simulated per round (default 128)")
    t.add_argument("--rounds", type=int, metavar="N",
                   help="search rounds (default 4)")
    t.add_argument("--mission", metavar="FILE", default="missions/paper_ellipse_004.toml",
                   help="the mission named in the printed run command")
    t.add_argument("--no-refine", dest="refine", action="store_false",
                   help="skip the tracking flight that refines the model")
    add_live_arguments(p, "the rover and the manoeuvre", required=True)
    p.set_defaults(func=run)


def _folder(text: str) -> Path:
    folder = Path(text)
    if folder.exists() and not folder.is_dir():
        raise UserError(f"--out {text}: not a directory")
    if not folder.resolve().parent.is_dir():
        raise UserError(f"--out {text}: no such directory {folder.resolve().parent}")
    folder.mkdir(exist_ok=True)
    return folder


REFINE_S = 30.0             # s of tracking flown to refine the model
REFINE_F_R = 0.08           # Hz: the paper's ellipse at the speed that tests the inner loops


def _refine_mission(space: float):
    """The paper's ellipse at 0.08 Hz, shrunk to stay within ``space`` of the start."""
    from .. import mission as missions
    k = min(1.0, 0.7 * space / 6.5)
    text = (f'name = "calibrate: tracking to refine the model"\nframe = "start"\n'
            f'duration = {REFINE_S}\n[trajectory]\nkind = "ellipse"\nf_r = {REFINE_F_R}\n'
            f'ax = {6 * k}\nbx = {-k}\nay = {2 * k}\nby = {3 * k}\n')
    return missions.loads(text, "<calibrate>")


def _children_cpu() -> float:
    """CPU seconds of this process's ended children (the tune's spawned workers)."""
    import os
    t = os.times()
    return t.children_user + t.children_system


NOTHING_ROBUST = ("calibrate: the tuner found no gains that hold on every neighbour of {vehicle} "
                  "(each limit-cycled or diverged on one): widen the search (--population 256 "
                  "--rounds 6), or check the identified limits in {vehicle} against the "
                  "autopilot's (a turn-rate or acceleration limit far below its parameter)")


def _tune(vehicle: Path, rate: float, command: str, args, log, pool=None):
    from ..app.vehicle import gains_for, load
    from ..sim.vehicle_gains import NothingRobust, tune_workers
    try:
        return gains_for(load(vehicle), rate, command, not args.quiet and not args.json, log,
                         pool, population=args.population, rounds=args.rounds,
                         workers=tune_workers())
    except NothingRobust:
        raise UserError(NOTHING_ROBUST.format(vehicle=vehicle)) from None


def _quick_gains(vehicle: Path, rate: float, command: str, log) -> Path:
    """Gains for the refining flight only (REFINE_SEARCH), in ``gains-refine.toml`` beside the
    vehicle file (removed before calibrate ends: ``run --vehicle`` must never find them)."""
    from ..app.vehicle import load, tune_and_record
    from ..sim.vehicle_gains import REFINE_SEARCH, NothingRobust
    try:
        gains = tune_and_record(load(vehicle), rate,
                                command + " (the refining flight's quick search)",
                                **REFINE_SEARCH)
    except NothingRobust:
        raise UserError(NOTHING_ROBUST.format(vehicle=vehicle)) from None
    out = vehicle.with_name(REFINE_GAINS)
    gains.save(out)
    log(f"quick gains for the refining flight: {out}")
    return out


REFINE_GAINS = "gains-refine.toml"


def _refine(options, args, vehicle: Path, report, log, gains_file: Path,
            timings: dict[str, float], cpu: dict[str, float]) -> dict:
    """Fly the refining track with ``gains_file`` and fit one model to the manoeuvre and the
    track together (see the module docstring). Returns what happened; on success ``vehicle``
    holds the joint fit. ``options``: the manoeuvre's flight options."""
    from ..app.flight import fly_mission
    from ..app.options import OutputOptions
    from ..ident.fit import rms
    from ..live.policy import GainOptions
    from .identify import FitOptions, identify_log
    folder = vehicle.parent
    # The vehicle's own gains and limits (no manoeuvre limits), at the manoeuvre's rate.
    flown = replace(options, vehicle_file=str(vehicle),
                    gains=GainOptions(rate=args.rate, gains_file=str(gains_file)),
                    output=OutputOptions(quiet=options.output.quiet))
    t0 = time.monotonic()
    result, paths = fly_mission(flown, _refine_mission(args.space))
    timings["refine_flight"] = time.monotonic() - t0
    if result.exit_code != ExitCode.OK or paths is None:
        return {"refined": False, "why": f"the tracking flight ended: {result.reason}"}
    refit = folder / "vehicle-refit.toml"
    joint_fit = FitOptions(out=str(refit))
    t0, c0 = time.monotonic(), time.process_time()
    joint = identify_log([report.log, paths.tlog], joint_fit, dict(report.autopilot), log)
    timings["joint_fit"] = time.monotonic() - t0
    cpu["joint_fit"] = time.process_time() - c0
    manoeuvre, track = joint.parts
    on_manoeuvre = rms(joint.fit.params, manoeuvre)
    on_track = rms(joint.fit.params, track)
    before = rms(report.fit.params, track)       # the manoeuvre's own model on the track
    out = {"tlog": str(paths.tlog),
           "check_speed_rms_m_s": on_manoeuvre[0], "check_yaw_rate_rms_rad_s": on_manoeuvre[1],
           "track_speed_rms_m_s": on_track[0], "track_yaw_rate_rms_rad_s": on_track[1],
           "track_speed_rms_before_m_s": before[0],
           "track_yaw_rate_rms_before_rad_s": before[1],
           "fit_speed_rms_m_s": joint.fit.speed_rms,
           "fit_yaw_rate_rms_rad_s": joint.fit.yaw_rate_rms}
    why = None
    # each flight explained as well as the profile asks of a manoeuvre (explain_limit)
    limit = report.profile.ident.explain_limit
    if max(on_manoeuvre[0], on_track[0]) > limit[0] or \
            max(on_manoeuvre[1], on_track[1]) > limit[1]:
        why = "the joint fit does not explain both flights"
    elif on_track[0] >= before[0]:
        why = "the joint fit predicts the track no better than the manoeuvre's model"
    if why is not None:
        refit.unlink()
        return {**out, "refined": False, "why": why}
    refit.replace(vehicle)
    return {**out, "refined": True}


EXCITED = {"speed": 0.3, "turn rate": 0.3}    # m/s, rad/s: a channel's setpoints span at least


def check_identified(report, space: float, log=lambda text: None) -> None:
    """A manoeuvre that did not excite a channel (its setpoints hardly moved), or a model that
    does not explain it (above the profile's ``explain_limit``): one line saying which and
    what to do (UserError, exit 2), before anything is tuned. A channel that was driven and is
    explained, but whose parameters the log does not pin, keeps its priors and says so."""
    import numpy as np

    from ..ident.determinacy import FITTED
    from ..ident.priors import SPEED_FIELDS, YAW_FIELDS
    f, series = report.fit, report.series
    ident = report.profile.ident
    hints, limits = ident.model_hints, ident.explain_limit
    commands = {"turn rate": series.yaw_rate_cmd, "speed": series.speed_cmd}
    if series.vector:       # PX4: the course loop makes the turn-rate setpoints of the heading
        commands["turn rate"] = np.unwrap(series.course_cmd)
    for channel in ("turn rate", "speed"):
        span = float(np.ptp(commands[channel]))
        if span < EXCITED[channel]:
            raise UserError(
                f"calibrate: the manoeuvre did not excite the {channel} channel (its setpoints "
                f"in {report.log} span {span:.2f}): give it more room (--space, now "
                f"{space:g} m) or check that the vehicle follows GUIDED {channel} setpoints")
    for channel, value, limit, unit in (("speed", f.speed_rms, limits[0], "m/s"),
                                        ("turn rate", f.yaw_rate_rms, limits[1], "rad/s")):
        if value > limit:
            raise UserError(
                f"calibrate: the model does not explain the manoeuvre's {channel} (RMS "
                f"{value:.3f} {unit}, more than {limit:g}){_overshoot(report, channel)}: the "
                f"vehicle does something the model lacks; check "
                f"{hints.get(channel, 'its inner-loop tuning')}, or fly another manoeuvre "
                f"(companion identify --connect ...) and look at --plot")
    for channel, fields in (("turn rate", YAW_FIELDS), ("speed", SPEED_FIELDS)):
        if not any(f.status.get(name) == FITTED for name in fields):
            log(f"the manoeuvre determined none of the {channel} channel's parameters: its "
                f"model keeps the priors (the vehicle file's [determined] says which)")


OVERSHOOT = 1.25        # a limit identified this far above the autopilot's own: it overshoots
CHANNEL_LIMITS = {"speed": ("max_speed", "max_accel"), "turn rate": ("max_yaw_rate",
                                                                     "max_yaw_accel")}


def _overshoot(report, channel: str) -> str:
    """What shows the vehicle overshooting its autopilot's own limits (a rate loop's
    feed-forward that overdrives it, which P and I then pull back, as ArduPilot SITL's
    rover-skid with ATC_STR_RAT_FF 0.5 does: docs/benchmarks-log.md), or ''."""
    f, priors = report.fit, report.priors
    for name in CHANNEL_LIMITS[channel]:
        fitted, prior = float(getattr(f.params, name)), getattr(priors.params, name)
        if prior is None or name not in priors.source or not 0 < float(prior) < float("inf"):
            continue
        if fitted > OVERSHOOT * float(prior):
            return (f"; its {channel} reaches {fitted:.3g}, {100 * (fitted / float(prior) - 1):.0f}"
                    f" % above {priors.describe(name)}: it overshoots the autopilot's own target")
    return ""


def _refine_and_tune(options, args, vehicle: Path, report, rate: float, command: str, log,
                     timings: dict[str, float], cpu: dict[str, float]):
    """Steps 2 and 3: the refining flight (unless --no-refine or --no-log), then the final
    tune: (the gains, what the refining did, the children's CPU before the tune)."""
    from ..sim.robust.pool import worker_pool
    from ..sim.vehicle_gains import tune_workers
    refined = {"refined": False, "why": "--no-refine" if not args.refine else "--no-log"}
    # the final tune's other processes start now and load what they need (2-3 s each) while
    # the refining tune and flight go on: they wait idle until the tune
    with worker_pool(tune_workers()) as pool:
        if args.refine and args.log:
            t0, c0 = time.monotonic(), time.process_time()
            quick = _quick_gains(vehicle, rate, command, log)
            timings["refine_tune"] = time.monotonic() - t0
            cpu["refine_tune"] = time.process_time() - c0
            log(f"refining: {REFINE_S:g} s of the paper's ellipse at {REFINE_F_R:g} Hz")
            try:
                refined = _refine(options, args, vehicle, report, log, quick, timings, cpu)
            finally:
                quick.unlink(missing_ok=True)
            log("refined: " + ("one model fitted to both flights" if refined["refined"]
                               else f"kept the manoeuvre's model ({refined['why']})"))
        t0, c0, w0 = time.monotonic(), time.process_time(), _children_cpu()
        gains = _tune(vehicle, rate, command, args, log, pool)
        timings["tune"] = time.monotonic() - t0
        cpu["tune"] = time.process_time() - c0
    return gains, refined, w0


def run(args) -> int:
    from ..app.flight import logger
    from ..live.policy import DEFAULT_RATE
    from ..sim.vehicle_gains import FINAL_SEARCH
    from .identify import FitOptions, _print, fly_and_fit, live_options
    args.population = FINAL_SEARCH["population"] if args.population is None else args.population
    args.rounds = FINAL_SEARCH["rounds"] if args.rounds is None else args.rounds
    if args.population < 8 or args.rounds < 1:
        raise UserError("--population must be at least 8 and --rounds at least 1")
    folder = _folder(args.out)
    vehicle = folder / "vehicle.toml"
    gains_path = folder / "gains.toml"
    for old in (gains_path, folder / REFINE_GAINS):   # would no longer match the new vehicle
        if old.exists():
            old.unlink()
    log = logger("companion calibrate", args.quiet)
    options = live_options(args)
    timings: dict[str, float] = {}      # s of wall time per step (docs/calibrate-and-identify.md)
    cpu: dict[str, float] = {}          # s of this process's CPU (what a busy machine stretches)
    t_start, cpu_start = time.monotonic(), time.process_time()
    code, report, flight = fly_and_fit(options, FitOptions(out=str(vehicle)), args.space)
    if report is None or code != ExitCode.OK:
        if report is not None:
            _print(report, args.json, flight)
        log("not tuned: the manoeuvre did not end normally")
        return code or ExitCode.FAULT
    timings["fit"] = report.fit_time_s
    cpu["fit"] = report.fit_cpu_s
    check_identified(report, args.space, log)
    timings["manoeuvre_flight"] = time.monotonic() - t_start - report.fit_time_s
    rate = args.rate or DEFAULT_RATE
    command = "companion " + shlex.join(sys.argv[1:]) if sys.argv[1:2] == ["calibrate"] \
        else f"companion calibrate --connect {args.connect} --out {args.out}"
    gains, refined, w0 = _refine_and_tune(options, args, vehicle, report, rate, command, log,
                                          timings, cpu)
    cpu["tune_workers"] = _children_cpu() - w0     # the other cores' share (tune_workers())
    timings["total"] = time.monotonic() - t_start
    cpu["total"] = time.process_time() - cpu_start
    log("wall time: " + ", ".join(f"{k.replace('_', ' ')} {v:.0f} s" for k, v in timings.items())
        + "; CPU: " + ", ".join(f"{k.replace('_', ' ')} {v:.0f} s" for k, v in cpu.items()))
    if Path(gains.source) != gains_path:
        raise UserError(f"{gains_path}: could not be written ({gains.source})")
    next_run = shlex.join(["companion", "run", "--connect", args.connect, "--vehicle",
                           str(vehicle), "--mission", args.mission, "--arm"])
    if args.json:
        from ..ident.record import as_dict
        print(json.dumps({"vehicle": str(vehicle), "gains": str(gains_path),
                          "identify": {**as_dict(report), "flight": flight},
                          "refine": refined, "timings_s": timings, "cpu_s": cpu,
                          "gains_header": gains.header.splitlines(), "next": next_run}))
        return ExitCode.OK
    _print(report, False, flight)
    print("refine      " + (f"one model fitted to the manoeuvre and {refined['tlog']} (on the "
                             f"manoeuvre {refined['check_speed_rms_m_s']:.3f} m/s, "
                             f"{refined['check_yaw_rate_rms_rad_s']:.3f} rad/s; on the track "
                             f"{refined['track_speed_rms_m_s']:.3f} m/s against "
                             f"{refined['track_speed_rms_before_m_s']:.3f} before)"
                             if refined["refined"] else f"not applied: {refined['why']}"))
    print(f"gains       {gains_path}")
    for line in gains.header.splitlines()[2:]:
        print(f"            {line}")
    print(f"next        {next_run}")
    return ExitCode.OK
