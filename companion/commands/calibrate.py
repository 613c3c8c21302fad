"""``companion calibrate``: one command for a new rover, identify it live, then tune for it.

    companion calibrate --connect URL --out DIR [--arm] [--space R] [identify's flags]

1. flies ``companion identify``'s excitation manoeuvre (within ``--space`` metres, at most 90 s,
   every failsafe of ``run``) and fits the vehicle model: ``DIR/vehicle.toml``;
2. tunes gains for that vehicle and its neighbours (``companion tune --vehicle``, about a minute
   on two cores): ``DIR/gains.toml``, recorded with the vehicle file's SHA-256;
3. prints the ``companion run --vehicle DIR/vehicle.toml`` command that flies with them.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from ..errors import UserError
from .identify import EPILOG, add_live_arguments


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "calibrate", help="identify a rover live and tune gains for it (vehicle.toml, gains.toml)",
        description=__doc__.split("\n\n", 1)[1], epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder for vehicle.toml and gains.toml (created if missing)")
    t = p.add_argument_group("tuning")
    t.add_argument("--population", type=int, default=160, metavar="N",
                   help="gain sets simulated per round (default 160)")
    t.add_argument("--rounds", type=int, default=5, metavar="N", help="search rounds (default 5)")
    t.add_argument("--mission", metavar="FILE", default="missions/paper_ellipse_004.toml",
                   help="the mission named in the printed run command")
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


def run(args) -> int:
    from ..progress import progress_bar
    from ..sim.vehicle_gains import gains_for
    from .identify import _print, fly_and_fit
    from .run import logger

    if args.population < 8 or args.rounds < 1:
        raise UserError("--population must be at least 8 and --rounds at least 1")
    folder = _folder(args.out)
    vehicle = folder / "vehicle.toml"
    gains_path = folder / "gains.toml"
    if gains_path.exists():      # an old gains file would no longer match the new vehicle
        gains_path.unlink()
    log = logger("companion calibrate", args.quiet)
    ident_args = argparse.Namespace(**{**vars(args), "out": str(vehicle)})
    code, report, flight = fly_and_fit(ident_args)
    if report is None or code != 0:
        if report is not None:
            _print(report, args.json, flight)
        log("not tuned: the manoeuvre did not end normally")
        return code or 3
    rate = args.rate or 40.0
    command = "companion " + shlex.join(sys.argv[1:]) if sys.argv[1:2] == ["calibrate"] \
        else f"companion calibrate --connect {args.connect} --out {args.out}"
    bar, progress = progress_bar(f"tuning for {vehicle}", not args.quiet and not args.json)
    try:
        gains = gains_for(vehicle, rate, command, progress, log, population=args.population,
                          rounds=args.rounds)
    finally:
        if bar is not None:
            bar.close()
    if Path(gains.source) != gains_path:
        raise UserError(f"{gains_path}: could not be written ({gains.source})")
    next_run = shlex.join(["companion", "run", "--connect", args.connect, "--vehicle",
                           str(vehicle), "--mission", args.mission, "--arm"])
    if args.json:
        from ..ident.record import as_dict
        print(json.dumps({"vehicle": str(vehicle), "gains": str(gains_path),
                          "identify": {**as_dict(report), "flight": flight},
                          "gains_header": gains.header.splitlines(), "next": next_run}))
        return 0
    _print(report, False, flight)
    print(f"gains       {gains_path}")
    for line in gains.header.splitlines()[2:]:
        print(f"            {line}")
    print(f"next        {next_run}")
    return 0
