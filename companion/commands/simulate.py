"""``companion simulate``: one rover, one mission, closed loop in simulation (no MAVLink).

Runs :func:`companion.sim.batch.simulate` with the mission's reference anchored at a rover at rest at
the origin facing north, and prints the paper's metrics f_cost and steady_rms (Section 5.3).

Rate, gains and limits are resolved by the one policy ``companion run`` uses
(:mod:`companion.live.policy`), so a simulation flies what a run would: ``--gains FILE``; the
mission's gains; the vehicle file's tuned gains (``--vehicle``, else the mission's [vehicle]
file); the shipped tuned gains for this rate, w_c and d_cen; the paper's. The plant is the
vehicle file's model, else the mission's [vehicle] (default the paper's, w_c 20 rad/s), with
--w-c / --d-cen overriding it.
"""

from __future__ import annotations

import json
import math
import sys

from ..app.arguments import add_controller_arguments
from ..core.tracker import Tracker
from ..errors import ExitCode, UserError, require_positive
from ..live.config import DEFAULT_RATE


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate", help="closed-loop simulation of one rover on a mission file",
        description="Simulate one rover tracking a mission (.toml, .plan, .waypoints) and print "
                    "f_cost and steady_rms.")
    p.add_argument("--mission", metavar="FILE",
                   help="mission file (default: the paper's ellipse at 0.12 Hz, 60 s)")
    p.add_argument("--rate", type=float, metavar="HZ",
                   help=f"controller rate (default: the mission's, else {DEFAULT_RATE:g})")
    p.add_argument("--w-c", type=float, dest="w_c", metavar="RAD_S",
                   help="actuator bandwidth of the simulated rover")
    p.add_argument("--d-cen", type=float, dest="d_cen", metavar="M",
                   help="distance from the tracked point to the wheel axle")
    p.add_argument("--gains", metavar="FILE", help="tuned-gains TOML file")
    p.add_argument("--vehicle", metavar="FILE",
                   help="the rover's vehicle file: the plant simulated, its tuned gains "
                        "(found beside it, else tuned now) and its limits, as run flies them")
    p.add_argument("--max-speed", type=float, dest="max_speed", metavar="M_S",
                   help="speed limit of every command (m/s)")
    p.add_argument("--max-yaw-rate", type=float, dest="max_yaw_rate", metavar="RAD_S",
                   help="turn-rate limit of every command (rad/s)")
    add_controller_arguments(p)
    p.add_argument("--origin", metavar="LAT,LON", help="EKF origin for geodetic missions")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", metavar="OUT.png", help="draw the run (path and error)")
    p.set_defaults(func=run)


class _Recorder:
    """Wraps a tracker and keeps what it saw at each control step (for --plot)."""

    def __init__(self, tracker: Tracker) -> None:
        self.tracker = tracker
        self.name = tracker.name
        self.log: dict[str, list[float]] = {k: [] for k in ("t", "x", "y", "x_ref", "y_ref")}

    @property
    def estimate(self):
        return self.tracker.estimate

    def reset(self) -> None:
        self.tracker.reset()
        for values in self.log.values():
            values.clear()

    def step(self, t, meas, ref):
        for key, value in (("t", t), ("x", meas.x), ("y", meas.y), ("x_ref", ref.x),
                           ("y_ref", ref.y)):
            self.log[key].append(float(value))
        return self.tracker.step(t, meas, ref)


def run(args) -> int:
    from .. import mission as missions
    from ..app.arguments import parse_origin
    from ..app.flight import known_vehicle, logger, print_warnings
    from ..app.vehicle import for_flight
    from ..live import policy
    from ..sim.batch import SimConfig, simulate
    from ..sim.plant import RoverParams

    require_positive("--rate", args.rate)
    require_positive("--w-c", args.w_c)
    require_positive("--max-speed", args.max_speed)
    require_positive("--max-yaw-rate", args.max_yaw_rate)
    if args.d_cen is not None and not (math.isfinite(args.d_cen) and args.d_cen >= 0):
        raise UserError(f"--d-cen must be a distance >= 0, not {args.d_cen!r}")
    if args.rate is not None and args.rate > 1000:
        raise UserError(f"--rate must be at most 1000 Hz, not {args.rate!r}")
    origin = parse_origin(args.origin)
    mission = (missions.load(args.mission, origin=origin) if args.mission
               else missions.paper_ellipse())
    print_warnings(mission, "companion simulate")

    options = sim_gain_options(args)
    policy.check_controller(args.controller, options)
    mission, loaded = for_flight(args.vehicle, mission)      # the vehicle file, read once
    vehicle = known_vehicle(loaded, mission, options, "companion simulate",
                            not args.json, logger("companion simulate", args.json),
                            args.controller)
    resolved = policy.resolve(mission, options, vehicle)
    rate, limits = resolved.rate, resolved.limits
    params = (loaded.params if loaded is not None
              else mission.vehicle or RoverParams.paper())
    if args.w_c is not None:
        params = params.with_(w_c=args.w_c)
    if args.d_cen is not None:
        params = params.with_(d_cen=args.d_cen)

    tracker, gains_values, gains_note = policy.build_tracker(args.controller, resolved.gains,
                                                             limits, options.controller_gains)
    if args.plot:
        tracker = _Recorder(tracker)

    config = SimConfig(duration=mission.duration, control_rate=rate)
    result = simulate(tracker, params, mission.anchored(0.0, 0.0, 0.0), config=config)
    f_cost, steady = float(result.f_cost), float(result.steady_rms)

    if args.plot:
        from ..mission.plot import plot_run
        plot_run(mission, tracker.log, args.plot,
                 f"{mission.name}: {args.controller} at {rate:g} Hz, steady RMS {steady:.3f} m")
    if args.json:
        print(json.dumps({"mission": mission.source, "rate_hz": rate, "f_cost": f_cost,
                          "steady_rms": steady, "duration_s": mission.duration,
                          "controller": args.controller, "gains": gains_note,
                          "gains_values": gains_values,
                          "limits": policy.limits_dict(limits)}))
    else:
        print(f"mission     {mission.name} ({mission.source})")
        print(f"controller  {args.controller} at {rate:g} Hz; gains: {gains_note}")
        print(f"plant       w_c {params.w_c:g} rad/s, d_cen {params.d_cen:g} m; "
              f"{mission.duration:.1f} s simulated")
        print(f"f_cost      {f_cost:.4f}")
        print(f"steady_rms  {steady:.4f} m")
        if args.plot:
            print(f"plot        {args.plot}")
    sys.stdout.flush()
    return ExitCode.OK


def sim_gain_options(args):
    """simulate's flags as the policy reads them (the same as run's for the same values)."""
    from ..app.arguments import controller_gains
    from ..live.policy import GainOptions
    return GainOptions(rate=args.rate, gains_file=args.gains, max_speed=args.max_speed,
                       max_yaw_rate=args.max_yaw_rate, w_c=args.w_c, d_cen=args.d_cen,
                       controller_gains=controller_gains(args.controller, args.controller_gains))
