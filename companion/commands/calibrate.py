"""``companion calibrate``: one command for a new rover, identify it live, then tune for it.

    companion calibrate --connect URL --out DIR [--arm] [--space R] [identify's flags]

1. flies ``companion identify``'s excitation manoeuvre (within ``--space`` metres, at most 90 s,
   every failsafe of ``run``) and fits the vehicle model: ``DIR/vehicle.toml``;
2. tunes gains for that vehicle and its neighbours (``companion tune --vehicle``, about a minute
   on two cores): ``DIR/gains.toml``, recorded with the vehicle file's SHA-256;
3. refines: flies the paper's ellipse at 0.08 Hz (shrunk to ``--space``) for 30 s with those
   gains, fits one model to the manoeuvre and that track together, and keeps it (then
   re-tunes) when it explains both flights within 0.15 m/s and 0.15 rad/s and predicts the
   track better than the manoeuvre's model did. Why: on ArduPilot SITL the manoeuvre alone
   reads the speed loop's delay long (0.22 s against 0.15 s from tracking: its speed steps
   start from rest) and its gains track the 0.08 Hz ellipse less well, while a model fitted to
   tracking alone misreads what tracking does not exercise (the turn/speed coupling) and
   mispredicts a faster track; the joint fit predicted held-out tracks at every speed as well as
   or better than either (``--no-refine`` skips this step; it needs the flight logs);
4. prints the ``companion run --vehicle DIR/vehicle.toml`` command that flies with them.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
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
                   help="gain sets simulated per round (default: the robust tuner's)")
    t.add_argument("--rounds", type=int, metavar="N",
                   help="search rounds (default: the robust tuner's)")
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
# m/s, rad/s: the joint fit must explain each flight this well (the held-out standard the
# identification is held to: issue 11's 0.15 m/s and 0.15 rad/s)
CHECK_LIMIT = (0.15, 0.15)


def _refine_mission(space: float):
    """The paper's ellipse at 0.08 Hz, shrunk to stay within ``space`` of the start."""
    from .. import mission as missions
    k = min(1.0, 0.7 * space / 6.5)
    text = (f'name = "calibrate: tracking to refine the model"\nframe = "start"\n'
            f'duration = {REFINE_S}\n[trajectory]\nkind = "ellipse"\nf_r = {REFINE_F_R}\n'
            f'ax = {6 * k}\nbx = {-k}\nay = {2 * k}\nby = {3 * k}\n')
    return missions.loads(text, "<calibrate>")


def _tune(vehicle: Path, rate: float, command: str, args, log):
    from .flight import gains_for_vehicle
    return gains_for_vehicle(vehicle, rate, command, not args.quiet and not args.json, log,
                             population=args.population, rounds=args.rounds)


def _refine(options, args, vehicle: Path, report, log) -> dict:
    """Fly the refining track with the tuned gains and fit one model to the manoeuvre and the
    track together (see the module docstring). Returns what happened; on success ``vehicle``
    holds the joint fit. ``options``: the manoeuvre's flight options."""
    from ..ident.fit import rms
    from ..live.policy import GainOptions
    from .flight import fly_mission
    from .identify import FitOptions, identify_log
    from .options import OutputOptions
    folder = vehicle.parent
    # The vehicle's own gains and limits (no manoeuvre limits), at the manoeuvre's rate.
    flown = replace(options, vehicle_file=str(vehicle), gains=GainOptions(rate=args.rate),
                    output=OutputOptions(quiet=options.output.quiet))
    result, paths = fly_mission(flown, _refine_mission(args.space))
    if result.exit_code != ExitCode.OK or paths is None:
        return {"refined": False, "why": f"the tracking flight ended: {result.reason}"}
    refit = folder / "vehicle-refit.toml"
    joint_fit = FitOptions(out=str(refit))
    joint = identify_log([report.log, paths.tlog], joint_fit, dict(report.autopilot), log)
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
    if max(on_manoeuvre[0], on_track[0]) > CHECK_LIMIT[0] or \
            max(on_manoeuvre[1], on_track[1]) > CHECK_LIMIT[1]:
        why = "the joint fit does not explain both flights"
    elif on_track[0] >= before[0]:
        why = "the joint fit predicts the track no better than the manoeuvre's model"
    if why is not None:
        refit.unlink()
        return {**out, "refined": False, "why": why}
    refit.replace(vehicle)
    return {**out, "refined": True}


def run(args) -> int:
    from ..live.policy import DEFAULT_RATE
    from ..sim.robust import RobustConfig
    from .flight import logger
    from .identify import FitOptions, _print, fly_and_fit, live_options
    args.population = RobustConfig.population if args.population is None else args.population
    args.rounds = RobustConfig.rounds if args.rounds is None else args.rounds
    if args.population < 8 or args.rounds < 1:
        raise UserError("--population must be at least 8 and --rounds at least 1")
    folder = _folder(args.out)
    vehicle = folder / "vehicle.toml"
    gains_path = folder / "gains.toml"
    if gains_path.exists():      # an old gains file would no longer match the new vehicle
        gains_path.unlink()
    log = logger("companion calibrate", args.quiet)
    options = live_options(args)
    code, report, flight = fly_and_fit(options, FitOptions(out=str(vehicle)), args.space)
    if report is None or code != ExitCode.OK:
        if report is not None:
            _print(report, args.json, flight)
        log("not tuned: the manoeuvre did not end normally")
        return code or ExitCode.FAULT
    rate = args.rate or DEFAULT_RATE
    command = "companion " + shlex.join(sys.argv[1:]) if sys.argv[1:2] == ["calibrate"] \
        else f"companion calibrate --connect {args.connect} --out {args.out}"
    gains = _tune(vehicle, rate, command, args, log)
    refined = {"refined": False, "why": "--no-refine" if not args.refine else "--no-log"}
    if args.refine and args.log:
        log(f"refining: {REFINE_S:g} s of the paper's ellipse at {REFINE_F_R:g} Hz with these gains")
        refined = _refine(options, args, vehicle, report, log)
        log("refined: " + ("one model fitted to both flights, re-tuned" if refined["refined"]
                           else f"kept the manoeuvre's model ({refined['why']})"))
        if refined["refined"]:
            gains_path.unlink()
            gains = _tune(vehicle, rate, command, args, log)
    if Path(gains.source) != gains_path:
        raise UserError(f"{gains_path}: could not be written ({gains.source})")
    next_run = shlex.join(["companion", "run", "--connect", args.connect, "--vehicle",
                           str(vehicle), "--mission", args.mission, "--arm"])
    if args.json:
        from ..ident.record import as_dict
        print(json.dumps({"vehicle": str(vehicle), "gains": str(gains_path),
                          "identify": {**as_dict(report), "flight": flight},
                          "refine": refined,
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
