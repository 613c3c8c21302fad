"""``companion simulate``: one rover, one mission, closed loop in simulation (no MAVLink).

Runs :func:`companion.sim.batch.simulate` with the mission's reference anchored at a rover at rest at
the origin facing north, and prints the paper's metrics f_cost and steady_rms (Section 5.3).

Gains, first found wins: ``--gains FILE``; the mission's own gains; the shipped tuned gains for
this rate, w_c and d_cen (:func:`companion.sim.gains.find_tuned`); else :data:`FALLBACK`.
The plant is the mission's [vehicle] (default the paper's, w_c 20 rad/s), with --w-c / --d-cen
overriding it; the mission's [limits] clamp the commands.
"""

from __future__ import annotations

import json
import math
import sys

from ..errors import UserError, require_positive

DEFAULT_RATE = 40.0


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
    p.add_argument("--controller", choices=("pzc", "pid", "kanayama"), default="pzc")
    p.add_argument("--origin", metavar="LAT,LON", help="EKF origin for geodetic missions")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", metavar="OUT.png", help="draw the run (path and error)")
    p.set_defaults(func=run)


def choose_gains(mission, rate: float, w_c: float, d_cen: float, gains_file: str | None):
    """(FilterGains, PZCGains, where they came from)."""
    from ..sim import gains as gains_mod
    from ..core.filter import FilterGains
    from ..core.pzc import PZCGains
    if gains_file is not None:
        tuned = gains_mod.load(gains_file)
        return tuned.filter, tuned.pzc, gains_file
    tuned = gains_mod.find_tuned(rate, w_c, d_cen) or gains_mod.find_tuned(rate, w_c)
    # Stand-in until tuned gains are shipped for this rate: feed-forward on, a filter slow
    # enough for a 40 Hz stream.
    base_filter = tuned.filter if tuned else FilterGains(k_df=200.0, lambda_f=40.0)
    base_pzc = tuned.pzc if tuned else PZCGains(velocity_ff=True, heading_rate_ff=True)
    where = tuned.source if tuned else "built-in stand-in (no tuned gains for this rate)"
    if mission.filter_gains is not None or mission.pzc_gains is not None:
        where = f"mission {mission.source}" + ("" if (mission.filter_gains and mission.pzc_gains)
                                               else f" + {where}")
    return (mission.filter_gains or base_filter, mission.pzc_gains or base_pzc, where)


class _Recorder:
    """Wraps a tracker and keeps what it saw at each control step (for --plot)."""

    def __init__(self, tracker):
        self.tracker = tracker
        self.log: dict[str, list[float]] = {k: [] for k in ("t", "x", "y", "x_ref", "y_ref")}

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
    from ..sim.batch import SimConfig, simulate
    from ..core.limits import Limits
    from ..sim.plant import RoverParams
    from .mission import parse_origin, print_warnings

    require_positive("--rate", args.rate)
    require_positive("--w-c", args.w_c)
    if args.d_cen is not None and not (math.isfinite(args.d_cen) and args.d_cen >= 0):
        raise UserError(f"--d-cen must be a distance >= 0, not {args.d_cen!r}")
    if args.rate is not None and args.rate > 1000:
        raise UserError(f"--rate must be at most 1000 Hz, not {args.rate!r}")
    origin = parse_origin(args.origin)
    mission = (missions.load(args.mission, origin=origin) if args.mission
               else missions.paper_ellipse())
    print_warnings(mission, "companion simulate")

    rate = args.rate or mission.rate_hz or DEFAULT_RATE
    params = mission.vehicle or RoverParams.paper()
    if args.w_c is not None:
        params = params.with_(w_c=args.w_c)
    if args.d_cen is not None:
        params = params.with_(d_cen=args.d_cen)
    limits = mission.limits or Limits()

    gains_note = ""
    if args.controller == "pzc":
        from ..core.pzc import PZCTracker
        fg, pg, gains_note = choose_gains(mission, rate, params.w_c, params.d_cen, args.gains)
        tracker = PZCTracker(fg, pg, limits)
    elif args.controller == "pid":
        from ..core.baselines import PIDGains, PIDTracker
        tracker, gains_note = PIDTracker(PIDGains(), limits), "paper's PID (k_P 3.5, k_I 0.5, k_D 0.5)"
    else:
        from ..core.baselines import KanayamaGains, KanayamaTracker
        tracker, gains_note = KanayamaTracker(KanayamaGains(), limits), "Kanayama defaults"
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
                          "controller": args.controller, "gains": gains_note}))
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
    return 0
