"""``companion run``: track a mission on a live vehicle (or the bundled plant) over MAVLink."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from ..errors import UserError

EPILOG = """\
precedence: flags > --gains FILE > the mission's gains > shipped tuned gains for the accepted
rate > the paper's gains (k_df 1000, lambda_f 120, k_dc 5, lambda_c 12). Rate: --rate > the
mission's rate_hz > the --gains file's > 40 Hz. Limits: flags > the mission's [limits] > 6 m/s,
6 rad/s.

exit codes: 0 mission done, or stopped on SIGTERM / Ctrl-C / abort after stopping the rover;
2 a user error (bad flag or file, no vehicle, no telemetry, no EKF origin for a mission placed
by latitude / longitude, --origin far from the vehicle's, the mission's start too far); 3
stopped by a fault (telemetry lost for --lost-timeout, vehicle restarted, non-finite command,
mode or arming refused, pilot took over). The rover is stopped (zero setpoint, then HOLD)
whenever the companion stops it.
"""


DEFAULT_START_DISTANCE = 25.0   # m: --max-start-distance


def positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, not {text}")
    return value


def non_negative(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, not {text}")
    return value


def add_gain_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("gains and limits")
    g.add_argument("--rate", type=positive, metavar="HZ",
                   help="telemetry / control rate to ask for (default: the mission's, else 40)")
    g.add_argument("--gains", metavar="FILE", help="tuned-gains TOML file (companion tune)")
    g.add_argument("--k-df", type=positive, dest="k_df", metavar="K", help="filter k_{d,f}")
    g.add_argument("--lambda-f", type=positive, dest="lambda_f", metavar="L", help="filter lambda_f")
    g.add_argument("--k-dc", type=positive, dest="k_dc", metavar="K", help="PZC k_{d,c}")
    g.add_argument("--lambda-c", type=positive, dest="lambda_c", metavar="L", help="PZC lambda_c")
    g.add_argument("--max-speed", type=positive, dest="max_speed", metavar="M_S",
                   help="speed limit of every setpoint (m/s)")
    g.add_argument("--max-yaw-rate", type=positive, dest="max_yaw_rate", metavar="RAD_S",
                   help="turn-rate limit of every setpoint (rad/s)")


def add_timeout_arguments(p: argparse.ArgumentParser) -> None:
    """The live loop's failsafe timeouts (companion run and identify)."""
    t = p.add_argument_group("timeouts (wall seconds)")
    t.add_argument("--stale-timeout", type=positive, default=0.5, metavar="S",
                   help="stop the rover when no valid sample arrives for S (default 0.5)")
    t.add_argument("--heartbeat-timeout", type=positive, default=10.0, metavar="S")
    t.add_argument("--telemetry-timeout", type=positive, default=10.0, metavar="S")
    t.add_argument("--arm-timeout", type=positive, default=60.0, metavar="S")
    t.add_argument("--lost-timeout", type=positive, default=30.0, metavar="S",
                   help="give up when telemetry stays lost for S (default 30)")


def add_safety_arguments(p: argparse.ArgumentParser) -> None:
    """Flight logs and MAVLink signing (companion run and demo)."""
    g = p.add_argument_group("flight log and signing")
    g.add_argument("--log-dir", metavar="DIR",
                   help="where the .tlog (all MAVLink traffic) and .csv (control loop) go "
                        "(default ./logs); written as they go, a crash loses at most 100 ms")
    g.add_argument("--no-log", dest="log", action="store_false", help="write no flight log")
    g.add_argument("--signing-key", metavar="FILE",
                   help="MAVLink 2 signing: 32-byte secret (raw or 64 hex digits, mode 600); "
                        "sign what is sent, refuse unsigned or wrongly signed input")


def open_flight_log(args, label: str, log) -> tuple[Any, list]:
    """(paths or None, [CSV sink]) for ``--log-dir`` / ``--no-log``; the paths are logged."""
    if not getattr(args, "log", True):
        return None, []
    from ..live.flightlog import new_paths, open_csv
    paths = new_paths(getattr(args, "log_dir", None), label)
    sink = open_csv(paths.csv)
    log(f"flight log: {paths.tlog} and {paths.csv}")
    return paths, [sink]


def signing_key(args) -> bytes | None:
    path = getattr(args, "signing_key", None)
    if path is None:
        return None
    from ..mav.signing import load_key
    return load_key(path)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "run", help="track a mission on a live vehicle over MAVLink",
        description="Connect to an ArduPilot or PX4 rover, stream LOCAL_POSITION_NED and "
                    "ATTITUDE, and send speed / yaw-rate setpoints from the model-free filter and "
                    "PZC law so the rover follows the mission.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--connect", metavar="URL", default="udpin:0.0.0.0:14550",
                   help="pymavlink connection string (default udpin:0.0.0.0:14550)")
    p.add_argument("--mission", metavar="FILE", required=True,
                   help="mission file (.toml, .plan, .waypoints)")
    g = p.add_argument_group(
        "where the mission is",
        "A mission placed by latitude / longitude (.plan, .waypoints, TOML frame\n"
        "\"geodetic\") is placed around the vehicle's own EKF origin, read from it\n"
        "(GPS_GLOBAL_ORIGIN / HOME_POSITION) after connecting.")
    g.add_argument("--origin", metavar="LAT,LON",
                   help="the EKF origin you expect: refused when more than 5 m from the "
                        "vehicle's; used as given only if the vehicle tells none")
    g.add_argument("--origin-timeout", type=positive, default=60.0, metavar="S",
                   help="wall s to wait for the vehicle's EKF origin (its GPS fix; default 60)")
    g.add_argument("--max-start-distance", type=non_negative, default=DEFAULT_START_DISTANCE,
                   metavar="M", help="refuse a mission whose first point is more than M m from "
                   f"the rover (default {DEFAULT_START_DISTANCE:g}; 0: no limit)")
    p.add_argument("--sysid", type=int, metavar="N",
                   help="system id of the vehicle to follow (default: the first heartbeat's)")
    p.add_argument("--arm", action="store_true",
                   help="arm the vehicle (retrying once a second); default: wait for it")
    add_gain_arguments(p)
    v = p.add_argument_group("vehicle (to pick tuned gains)")
    v.add_argument("--vehicle", metavar="FILE",
                   help="the rover's vehicle file (companion identify / calibrate): its gains "
                        "(found beside it, else tuned now and stored there) and its limits; "
                        "default: the mission's [vehicle] file")
    v.add_argument("--w-c", type=positive, dest="w_c", metavar="RAD_S",
                   help="speed-loop bandwidth (default: the mission's [vehicle], else 20)")
    v.add_argument("--d-cen", type=non_negative, dest="d_cen", metavar="M",
                   help="axle to tracked point (default: the mission's [vehicle], else 0)")
    add_timeout_arguments(p)
    add_safety_arguments(p)
    p.add_argument("--realtime", action="store_true",
                   help="run the control loop under SCHED_FIFO (Linux; needs root or "
                        "CAP_SYS_NICE); for kHz loops on a busy board")
    o = p.add_argument_group("output")
    o.add_argument("--json", action="store_true", help="print one JSON result object at the end")
    o.add_argument("--progress", action="store_true", help="progress bar on stderr")
    o.add_argument("-q", "--quiet", action="store_true", help="no log lines on stderr")
    from .zenoh_args import add_zenoh_arguments
    add_zenoh_arguments(p)
    allow_negative_pairs(p)
    p.set_defaults(func=run)


def allow_negative_pairs(parser: argparse.ArgumentParser) -> None:
    """Let ``--origin -35.36,149.16`` (southern / western) be a value, as argparse already lets
    ``-35.36`` be: its test for a negative number knows no comma-separated list."""
    import re
    parser._negative_number_matcher = re.compile(r"^-\d*\.?\d+(,-?\d*\.?\d+)*$")


def vehicle_choice(args, mission, log) -> tuple[object, object]:
    """The gains and limits of the vehicle file (``--vehicle``, else the mission's), or
    (None, None). Gains are looked up only when no --gains file overrides them; tuning on the
    spot shows a progress bar."""
    path = getattr(args, "vehicle", None) or mission.vehicle_file
    if path is None:
        return None, None
    from ..sim import vehicle_file
    from ..sim.vehicle_gains import vehicle_limits
    vehicle = vehicle_file.load(path).params
    limits = vehicle_limits(vehicle)
    if args.gains:
        return None, limits
    rate = args.rate or mission.rate_hz or 40.0
    return gains_for_vehicle(path, rate, f"companion run --vehicle {path} (tuned on first use)",
                             not getattr(args, "quiet", False), log), limits


def gains_for_vehicle(path, rate: float, command: str, show_bar: bool, log, **search):
    """The gains tuned for a vehicle file (found beside it, else tuned now and stored there,
    with a progress bar): shared by run, demo and calibrate."""
    from ..progress import progress_bar
    from ..sim.vehicle_gains import gains_for
    with progress_bar(f"tuning for {Path(path).name}", show_bar) as progress:
        return gains_for(path, rate, command, progress, log, **search)


def settings_from_args(args, mission, url: str, key: bytes | None = None,
                       tlog: str | None = None, vehicle: tuple = (None, None)):
    from ..live.link import LinkConfig
    from ..live.runner import RunnerConfig
    from ..live.session import GainFlags, RunSettings
    return RunSettings(
        link=LinkConfig(url=url, sysid=getattr(args, "sysid", None),
                        heartbeat_timeout=getattr(args, "heartbeat_timeout", 10.0),
                        signing_key=key, tlog=tlog),
        mission=mission,
        runner=RunnerConfig(stale_timeout=getattr(args, "stale_timeout", 0.5),
                            arm=getattr(args, "arm", True),
                            telemetry_timeout=getattr(args, "telemetry_timeout", 10.0),
                            arm_timeout=getattr(args, "arm_timeout", 60.0),
                            lost_timeout=getattr(args, "lost_timeout", 30.0),
                            max_start_distance=start_limit(args)),
        rate=args.rate, gains_file=args.gains,
        gain_flags=GainFlags(args.k_df, args.lambda_f, args.k_dc, args.lambda_c),
        max_speed=args.max_speed, max_yaw_rate=args.max_yaw_rate,
        realtime=getattr(args, "realtime", False),
        w_c=getattr(args, "w_c", None), d_cen=getattr(args, "d_cen", None),
        vehicle_gains=vehicle[0], vehicle_limits=vehicle[1],
        origin=parse_origin(getattr(args, "origin", None)),
        origin_timeout=getattr(args, "origin_timeout", 60.0))


def start_limit(args) -> float:
    """--max-start-distance in metres; 0 (and commands without the flag): no limit."""
    limit = getattr(args, "max_start_distance", None)
    return math.inf if not limit else float(limit)


def parse_origin(text: str | None) -> tuple[float, float] | None:
    from .mission import parse_origin as parse
    return parse(text)


def logger(prefix: str, quiet: bool):
    if quiet:
        return lambda text: None

    def log(text: str) -> None:
        print(f"{prefix}: {text}", file=sys.stderr, flush=True)
    return log


def install_signals(switch):
    """SIGTERM and SIGINT stop the rover and end the run; returns a function that undoes it."""
    import signal

    def handler(signum, frame):
        switch.trigger(signal.Signals(signum).name)

    old = {sig: signal.signal(sig, handler) for sig in (signal.SIGTERM, signal.SIGINT)}
    return lambda: [signal.signal(sig, h) for sig, h in old.items()]


def print_result(result, as_json: bool, extra: dict | None = None) -> None:
    d = result.as_dict()
    if extra:
        d.update(extra)
    if as_json:
        print(json.dumps(d), flush=True)
        return
    def ms(x):
        return "n/a" if x is None else f"{x:.3f} ms"
    rejected = {k: v for k, v in d["telemetry_rejected"].items() if v}
    lines = [
        f"result      {d['reason']} (exit {d['exit_code']})",
        f"mission     {d['mission']}: {d['duration_s']:.2f} s tracked",
        f"tracking    f_cost {d['f_cost']:.4f}, steady RMS "
        + ("n/a" if d['steady_rms'] is None else f"{d['steady_rms']:.4f} m"),
        f"loop        {d['cycles']} cycles at "
        + ("n/a" if d['loop_rate_hz'] is None else f"{d['loop_rate_hz']:.1f} Hz")
        + f" (asked {d['rate_requested_hz']:g} Hz, vehicle accepted "
        + (f"{d['rate_accepted_hz']:g} Hz)" if d['rate_accepted_hz'] else "nothing)"),
        f"latency     p50 {ms(d['latency_p50_ms'])}, p99 {ms(d['latency_p99_ms'])}, "
        f"max {ms(d['latency_max_ms'])} (telemetry read to setpoint sent)",
        f"telemetry   {d['telemetry_received']} received, "
        f"{sum(rejected.values())} refused {rejected or ''}; {d['missed_cycles']} missed cycles",
        f"setpoints   {d['setpoints_sent']} sent; failsafes {d['failsafes']}; "
        f"HOLD {'confirmed' if d['hold_confirmed'] else 'not confirmed'}",
        f"gains       {d['gains_source']}",
    ]
    if d.get("ekf_origin"):
        o = d["ekf_origin"]
        lines.append(f"origin      {o['lat']:.7f}, {o['lon']:.7f} ({o['source']}): the mission "
                     "placed around it")
    for key in ("plot", "tlog", "csv"):
        if key in d:
            lines.append(f"{key:<11} {d[key]}")
    print("\n".join(lines), flush=True)


def load_mission(path: str, origin_text: str | None):
    """The mission file read and checked before connecting (a bad one fails early); one
    placed by latitude / longitude is placed again around the vehicle's EKF origin once it is
    known (companion.live.origin)."""
    from .. import mission as missions
    from .mission import print_warnings
    mission = missions.load(path, origin=parse_origin(origin_text))
    print_warnings(mission, "companion run")
    return mission


def run(args) -> int:
    mission = load_mission(args.mission, args.origin)
    result, paths = fly_mission(args, mission)
    if result.exit_code == 2:
        raise UserError(result.reason)
    print_result(result, args.json, {"tlog": paths.tlog, "csv": paths.csv} if paths else None)
    return result.exit_code


def fly_mission(args, mission):
    """Fly ``mission`` with run's flags: (the result, the flight log's paths or None). Also used
    by ``calibrate`` for its refining flight."""
    from ..bus import open_bus, shut
    from ..progress import ProgressSink
    from ..live.session import StopSwitch, fly
    from .zenoh_args import bus_options

    key = signing_key(args)
    log = logger("companion run", args.quiet)
    vehicle = vehicle_choice(args, mission, log)     # before connecting: may tune for a minute
    switch = StopSwitch()
    restore = install_signals(switch)
    bus, log_sinks, paths = None, [], None
    try:
        bus = open_bus(bus_options(args), log)   # inside the try: closed on every path out
        # The flight log once every flag has been checked: a bad one leaves no empty log.
        paths, log_sinks = open_flight_log(args, "run", log)
        settings = settings_from_args(args, mission, args.connect, key,
                                      paths.tlog if paths else None, vehicle)
        sinks = list(log_sinks)
        if args.progress:
            sinks.append(ProgressSink(mission.duration, mission.name))
        result = fly(settings, sinks=sinks + ([bus] if bus else []), log=log, switch=switch,
                     control=bus.control if bus else None)
    finally:
        shut(bus)
        restore()
        for sink in log_sinks:
            sink.close()    # idempotent: the loop closed it unless the set-up failed
    return result, paths
