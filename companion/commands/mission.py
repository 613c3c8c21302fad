"""``companion mission check FILE...`` and ``companion mission show FILE [--plot OUT.png]``.

``check`` validates each file (TOML mission, QGroundControl .plan, QGC WPL 110 .waypoints) and
prints one summary line per good file; each bad file gets one error line and the exit code is 2.
With ``--vehicle FILE`` each reference is also checked against that vehicle
(:mod:`companion.mission.feasibility`): one line per problem (tighter than its minimum turning
radius, slowing faster than it can, ...) and exit 3 when any reference is out of its reach.
``show`` prints what a mission holds and can draw its path with time marks.
"""

from __future__ import annotations

import argparse
import sys

from ..errors import ExitCode, UserError


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "mission", help="check or show mission files (.toml, .plan, .waypoints)",
        description="Check mission files before anything moves, or show one.")
    sub = parser.add_subparsers(dest="mission_command", metavar="ACTION", required=True)

    check = sub.add_parser("check", help="validate files and print a one-line summary of each")
    check.add_argument("files", nargs="+", metavar="FILE")
    check.add_argument("--vehicle", metavar="FILE",
                       help="also check each reference against this vehicle file (companion "
                            "identify / calibrate): tighter than its minimum turning radius, "
                            "faster than it can slow down, speed up or turn, above its top "
                            "speed; exit 3 when a reference is out of its reach")
    _common(check)
    check.set_defaults(func=run_check)

    show = sub.add_parser("show", help="describe a mission and optionally plot its path")
    show.add_argument("file", metavar="FILE")
    show.add_argument("--plot", metavar="OUT.png", help="draw the path with time marks")
    show.add_argument("--every", type=float, default=None, metavar="S",
                      help="seconds between time marks on the plot (default: about 10 marks)")
    _common(show)
    show.set_defaults(func=run_show)

    from . import mission_pull
    mission_pull.register(sub)


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--origin", metavar="LAT,LON",
                        help="EKF origin for geodetic files (default: the plan's home)")
    parser.add_argument("--speed", type=float, metavar="M_S",
                        help="speed for imported .plan / .waypoints (default: the file's)")


def _check_speed(speed: float | None) -> None:
    import math
    if speed is not None and not (math.isfinite(speed) and 0 < speed <= 100):
        raise UserError(f"--speed must be a speed in (0, 100] m/s, not {speed!r}")


def run_check(args) -> int:
    from .. import mission as missions
    from ..app.arguments import parse_origin
    from ..app.flight import print_warnings
    origin = parse_origin(args.origin)
    _check_speed(args.speed)
    from ..app.vehicle import for_flight
    from ..app.vehicle import load as load_vehicle
    vehicle = load_vehicle(args.vehicle).params if args.vehicle else None
    failed = out_of_reach = 0
    for name in args.files:
        try:
            m, _ = for_flight(None, missions.load(name, origin=origin, speed=args.speed))
        except UserError as err:
            print(f"companion mission: error: {err}", file=sys.stderr)
            failed += 1
            continue
        print_warnings(m)
        problems = []
        if vehicle is not None:
            from ..mission.feasibility import check
            problems = check(m.trajectory, m.duration, vehicle)
        if problems:
            out_of_reach += 1
            for p in problems:
                print(f"{name}: out of reach for {args.vehicle}: {p.describe()}", flush=True)
            continue
        print(f"{name}: ok: {m.summary()}" + (f"; within {args.vehicle}'s reach"
                                               if vehicle is not None else ""), flush=True)
    return (ExitCode.USER_ERROR if failed else
            ExitCode.OUT_OF_REACH if out_of_reach else ExitCode.OK)


def run_show(args) -> int:
    import math

    from .. import mission as missions
    from ..app.arguments import parse_origin
    from ..app.flight import print_warnings
    origin = parse_origin(args.origin)
    _check_speed(args.speed)
    if args.every is not None and not (math.isfinite(args.every) and args.every > 0):
        raise UserError(f"--every must be a positive number of seconds, not {args.every!r}")
    from ..app.vehicle import for_flight
    m, _ = for_flight(None, missions.load(args.file, origin=origin, speed=args.speed))
    print_warnings(m)
    for key, value in describe(m):
        print(f"{key:<12} {value}")
    if args.plot:
        from ..mission.plot import plot_mission
        plot_mission(m, args.plot, every=args.every)
        print(f"{'plot':<12} {args.plot}")
    return 0


def describe(m) -> list[tuple[str, str]]:
    """(label, text) lines describing a mission."""
    rows = [("name", m.name), ("source", m.source)]
    if m.description:
        rows.append(("description", m.description))
    rows += [("trajectory", m.kind), ("frame", m.frame), ("duration", f"{m.duration:.2f} s")]
    if m.period is not None:
        rows.append(("period", f"{m.period:.2f} s per lap ({m.duration / m.period:.2f} laps)"))
    if m.profile is not None:
        rows += [("length", f"{m.profile.length:.1f} m"),
                 ("peak speed", f"{m.profile.peak_speed:.3f} m/s"),
                 ("turn rate", f"{m.profile.peak_turn_rate:.3f} rad/s (peak)")]
    start = m.anchored(0.0, 0.0, 0.0).sample(0.0)
    rows.append(("starts at", f"({round(start.x, 2) + 0.0:.2f}, {round(start.y, 2) + 0.0:.2f}) m north, east"))
    if m.limits is not None:
        rows.append(("limits", f"max_speed {m.limits.max_speed:g} m/s, "
                               f"max_yaw_rate {m.limits.max_yaw_rate:g} rad/s"))
    rows.append(("rate", f"{m.rate_hz:g} Hz" if m.rate_hz else "companion default"))
    if m.filter_gains is not None:
        rows.append(("filter", f"k_df {m.filter_gains.k_df:g}, lambda_f {m.filter_gains.lambda_f:g}"))
    if m.pzc_gains is not None:
        rows.append(("pzc", f"k_dc {m.pzc_gains.k_dc:g}, lambda_c {m.pzc_gains.lambda_c:g}"))
    if m.vehicle is not None:
        rows.append(("vehicle", f"d_cen {m.vehicle.d_cen:g} m, w_c {m.vehicle.w_c:g} rad/s"))
    return rows
