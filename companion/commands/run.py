"""``companion run``: track a mission on a live vehicle (or the bundled plant) over MAVLink."""

from __future__ import annotations

import argparse

from ..app.arguments import (
    add_gain_arguments,
    add_gcs_arguments,
    add_link_arguments,
    add_origin_arguments,
    add_output_arguments,
    add_safety_arguments,
    add_timeout_arguments,
    add_vehicle_arguments,
    add_zenoh_arguments,
)

EPILOG = """\
precedence (companion.live.policy): flags > --gains FILE > the mission's gains > the vehicle
file's gains > shipped tuned gains for the accepted rate > the paper's gains (k_df 1000,
lambda_f 120, k_dc 5, lambda_c 12). Rate: --rate > the mission's rate_hz > the --gains file's
> 40 Hz. Limits: flags > the lower of the mission's [limits] and the vehicle file's > 6 m/s,
6 rad/s.

exit codes: 0 mission done, or stopped on SIGTERM / Ctrl-C / abort
after stopping the rover; 2 a user error (bad flag or file, no vehicle, no telemetry, no EKF
origin for a mission placed by latitude / longitude, --origin far from the vehicle's, the
mission's start too far); 3 stopped by the companion's own failsafe (telemetry lost for
--lost-timeout, non-finite command, mode or arming refused); 4 pilot took over (a pilot or
ground station changed the mode or disarmed); 5 the autopilot's own failsafe (EKF, GCS,
battery, fence, radio) took the vehicle: not taken back; 6 the position estimate flagged or
stepped (GPS glitch or loss) and --on-bad-estimate end, or unhealthy for --lost-timeout; 7
vehicle restarted mid-mission. The rover is stopped (zero setpoint, then HOLD) whenever the
companion stops it; after 4 and 5 it sends nothing more.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "run", help="track a mission on a live vehicle over MAVLink",
        description="Connect to an ArduPilot or PX4 rover, stream LOCAL_POSITION_NED and "
                    "ATTITUDE, and send speed / yaw-rate setpoints from the model-free filter and "
                    "PZC law so the rover follows the mission.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_link_arguments(p, default_connect=True)
    p.add_argument("--mission", metavar="FILE", required=True,
                   help="mission file (.toml, .plan, .waypoints), or 'vehicle': the mission "
                        "stored on the vehicle, pulled at start (companion mission pull)")
    add_origin_arguments(p)
    add_gcs_arguments(p)
    add_gain_arguments(p)
    add_vehicle_arguments(p)
    add_timeout_arguments(p)
    add_safety_arguments(p)
    p.add_argument("--realtime", action="store_true",
                   help="run the control loop under SCHED_FIFO (Linux; needs root or "
                        "CAP_SYS_NICE); for kHz loops on a busy board")
    add_output_arguments(p, progress=True)
    add_zenoh_arguments(p)
    from ..app.config_file import add_config_arguments
    add_config_arguments(p)    # every flag above (and any added later) is a config key
    p.set_defaults(func=run)


def run(args) -> int:
    from ..app.flight import fly_mission, load_mission
    from ..app.options import FlightOptions
    from ..app.run_result import print_result
    options = FlightOptions.from_args(args)
    path, handover = args.mission, None
    if args.handover and path != "vehicle":
        from ..errors import UserError
        raise UserError(f"--handover flies the mission stored on the vehicle: give --mission "
                        f"vehicle, not {path!r}")
    if path == "vehicle" or args.handover:
        from ..app.flight import logger
        from .mission_pull import handover_plan, vehicle_mission_file
        pulled_path, pulled = vehicle_mission_file(options, logger("companion run",
                                                                   options.output.quiet))
        path = str(pulled_path)
        if args.handover:
            handover = handover_plan(pulled)
            options = options.for_handover(handover, pulled.profile.auto_mode)
    mission = load_mission(path, args.origin)
    result, paths = fly_mission(options, mission)
    print_result(result, options.output.json,
                 {"tlog": paths.tlog, "csv": paths.csv, "mcap": paths.mcap} if paths else None)
    return result.exit_code
