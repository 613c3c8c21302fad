"""``companion demo``: the bundled plant and the companion, two processes over loopback UDP.

Starts ``sitl-plant`` (the paper's rover behind an ArduPilot-like MAVLink autopilot) pushing to a
free loopback port, and runs the companion's control loop in this process against it, exactly as
``companion run`` would: heartbeat, rates, GUIDED, arm, track, zero setpoint and HOLD at the end.

Defaults: the paper's ellipse at f_r = 0.12 Hz for 60 s (Section 5) on the paper's plant with
d_cen = 0.3 m (Section 5.2; with d_cen = 0 the tracked point sits on the axle and cannot move
sideways, which a 40 Hz loop tracks far less well), 40 Hz telemetry, and the plant in lockstep:
it advances one telemetry tick per setpoint, so the run is deterministic and takes a few seconds
(``--speedup N`` without ``--lockstep`` runs it paced, N x real time).
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

from .. import profiles
from ..app.arguments import (
    add_gain_arguments,
    add_safety_arguments,
    add_zenoh_arguments,
    non_negative,
    positive,
)
from ..errors import UserError

DEFAULT_D_CEN = 0.3


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "demo", help="fly the paper's ellipse: bundled plant + companion over loopback UDP",
        description=__doc__.split("\n\n", 1)[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--mission", metavar="FILE",
                   help="mission file (default: the paper's ellipse, f_r 0.12 Hz, 60 s)")
    p.add_argument("--duration", type=positive, metavar="S", help="track only S seconds")
    p.add_argument("--preset", choices=("paper", "stock", "ardupilot-skid"), default="paper",
                   help="plant: the paper's rover (default), a stock ArduPilot skid-steer as a "
                        "linear lag, or SITL rover-skid as identified (ardupilot-skid)")
    p.add_argument("--vehicle", metavar="FILE",
                   help="plant: a vehicle file (companion identify) instead of a preset")
    p.add_argument("--d-cen", type=non_negative, dest="d_cen", default=DEFAULT_D_CEN, metavar="M",
                   help=f"plant's axle-to-tracked-point distance (default {DEFAULT_D_CEN:g})")
    p.add_argument("--autopilot", choices=list(profiles.AUTOPILOTS),
                   default=profiles.DEFAULT_AUTOPILOT)
    p.add_argument("--lockstep", action=argparse.BooleanOptionalAction, default=None,
                   help="plant waits for each setpoint (default on, off when --speedup is given)")
    p.add_argument("--speedup", type=positive, metavar="N", help="plant runs N x real time")
    add_gain_arguments(p)
    add_safety_arguments(p)
    p.add_argument("--out", metavar="DIR", default="out", help="where the plot goes (default out/)")
    p.add_argument("--no-plot", dest="plot", action="store_false", help="skip the plot")
    p.add_argument("--json", action="store_true", help="print one JSON result object")
    p.add_argument("-q", "--quiet", action="store_true", help="no log lines on stderr")
    add_zenoh_arguments(p)
    from ..app.config_file import add_config_arguments
    add_config_arguments(p)
    p.set_defaults(func=run)


def _free_port() -> int:
    import socket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _mission(args):
    from .. import mission as missions
    from ..app.flight import load_mission
    mission = (load_mission(args.mission, None, "companion demo") if args.mission
               else missions.paper_ellipse(0.12, 60.0))
    if args.duration is not None:
        mission = replace(mission, duration=args.duration)
    return mission


def plant_argv(args, port: int, rate: float) -> list[str]:
    lockstep = args.lockstep if args.lockstep is not None else args.speedup is None
    # The plant refuses rates above 0.8 x its loop rate, like ArduPilot; give it a loop fast
    # enough for the rate asked (a real vehicle may not be, and the companion then falls back).
    loop_rate = max(50.0, math.ceil(rate / 0.8) + 1)
    argv = [sys.executable, "-m", "sitl_plant", "--connect", f"udpout:127.0.0.1:{port}",
            "--preset", args.preset, "--d-cen", repr(args.d_cen), "--autopilot", args.autopilot,
            "--loop-rate", f"{loop_rate:g}"]
    if args.vehicle:
        # an identified vehicle is a real one: its autopilot may send on scheduler ticks
        ticks = profiles.autopilot_named(args.autopilot).plant.tick_aligned
        argv += ["--vehicle", args.vehicle] + (["--tick-aligned"] if ticks else [])
    if lockstep:
        argv.append("--lockstep")
    if args.speedup is not None:
        argv += ["--speedup", repr(args.speedup)]
    if args.signing_key:
        argv += ["--signing-key", args.signing_key]
    return argv


def _stop(proc: subprocess.Popen) -> int | None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=3.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


def run(args) -> int:
    from ..app.flight import Flight, known_vehicle, logger, refuse_user_error
    from ..app.options import FlightOptions, OutputOptions, bus_options, gain_options, log_options
    from ..app.run_result import print_result
    from ..app.vehicle import bundled, for_flight
    from ..app.vehicle import load as load_vehicle
    from ..live.config import LinkConfig, RunnerConfig
    from ..live.policy import requested_rate
    from ..progress import TraceSink
    from ..sim import vehicle_file
    from ..vehicle import vehicle_limits

    # the plant's vehicle: --vehicle, else the preset (a bundled file, or a built-in model)
    own = load_vehicle(args.vehicle) if args.vehicle else bundled(args.preset)
    mission, _ = for_flight(None, _mission(args))
    params = own.params if own is not None else vehicle_file.preset(args.preset)
    log = logger("companion demo", args.quiet)
    # The plant is the vehicle: its w_c and d_cen pick shipped gains, its limits bound the
    # setpoints (so the anti-windup knows where it saturates).
    gains = replace(gain_options(args, vehicle=False), w_c=float(params.w_c), d_cen=args.d_cen)
    # An identified vehicle (--vehicle, or a preset made from one) flies the gains tuned for it,
    # as `companion run --vehicle` does: shipped beside the preset, else tuned now.
    vehicle = known_vehicle(own, mission, gains, "companion demo",
                            not args.quiet and not args.json, log, args.controller)
    vehicle = replace(vehicle, limits=vehicle_limits(params))
    port = _free_port()
    options = FlightOptions(
        link=LinkConfig(url=f"udpin:127.0.0.1:{port}", heartbeat_timeout=15.0),
        runner=RunnerConfig(arm=True), gains=gains, controller=args.controller,
        signing_key_file=args.signing_key,
        log=log_options(args), output=OutputOptions(json=args.json, progress=True,
                                                    quiet=args.quiet),
        bus=bus_options(args),
        # the flight record names the vehicle file flown (the demo has its own vehicle)
        vehicle_file=own.path if own is not None else None)
    flight = Flight(options, "demo", log)          # a bad signing key fails here
    argv = plant_argv(args, port, requested_rate(mission, gains))
    if mission.geodetic:
        # The plant's EKF origin at the mission's own (a plan's home): it starts where drawn.
        argv.append(f"--origin={mission.datum[0]:.7f},{mission.datum[1]:.7f}")
    trace = TraceSink()

    log(f"plant: {' '.join(argv[2:])}")
    plant_log = tempfile.TemporaryFile(mode="w+")
    plant = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=plant_log,
                             env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        with flight:     # a bad --zenoh-* flag or file fails here: its own message says which
            try:
                result = flight.fly(mission, vehicle, sinks=[trace], loaded=own)
            except UserError as err:
                if plant.poll() is not None:
                    plant_log.seek(0)
                    last = (plant_log.read().strip().splitlines() or ["(no output)"])[-1]
                    raise UserError(f"the plant exited ({plant.returncode}): {last}") from None
                raise UserError(f"{err} (plant: {' '.join(argv[2:])})") from None
    finally:
        plant_code = _stop(plant)
        plant_log.close()

    refuse_user_error(result)
    extra = {"plant": " ".join(argv[2:]), "plant_exit": plant_code, "preset": args.preset,
             "d_cen": args.d_cen}
    if flight.paths is not None:
        extra.update(tlog=flight.paths.tlog, csv=flight.paths.csv, mcap=flight.paths.mcap)
    if args.plot and trace.log["t"]:
        from ..mission.plot import plot_run
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        path = out / "demo.png"
        steady = result.steady_rms
        plot_run(mission, trace.log, str(path),
                 f"{mission.name} over MAVLink, {result.loop_rate_hz:.0f} Hz: f_cost "
                 f"{result.f_cost:.3f}, steady RMS {steady:.3f} m")
        extra["plot"] = str(path)
    print_result(result, args.json, extra)
    return result.exit_code
