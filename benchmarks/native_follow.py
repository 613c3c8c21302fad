"""ArduPilot's (or PX4's) own trajectory following, the alternative a rover builder would otherwise use.

Streams the mission's reference as GUIDED position targets (SET_POSITION_TARGET_LOCAL_NED,
LOCAL_NED, position only, type_mask 3580; ArduPilot's AR_WPNav / AR_PosControl does the rest) at
the telemetry rate, anchored at the rover's start pose exactly as ``companion run`` anchors it,
and prints the paper's tracking figures from the vehicle's own LOCAL_POSITION_NED: f_cost and
the steady RMS over the last half. With ``--velocity`` the reference velocity goes along as
feed-forward (type_mask 3576), which AR_PosControl also accepts.

PX4 (told from the heartbeat): OFFBOARD position targets with the reference velocity as
feed-forward (LOCAL_NED, x, y, vx, vy; type_mask 3556), streamed for a second before OFFBOARD is
asked for (PX4's proof of life), at the rover's current position until armed. PX4's Ackermann
rover (rover_ackermann, AckermannOffboardMode) drives to the position with its pure-pursuit
position controller and uses the velocity only when no position is given, so this is PX4's
position following; PX4 is left in Hold (AUTO.LOITER) at the end.

    python benchmarks/native_follow.py --connect tcp:127.0.0.1:5760 --f-r 0.04 [--arm] [--json]

Prints figures, asserts nothing; the vehicle is left stopped in HOLD.
"""

from __future__ import annotations

import argparse
import json
import sys

from companion import mission as missions
from testbed.baselines import follow


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--connect", required=True, help="pymavlink URL of the autopilot")
    p.add_argument("--f-r", type=float, default=0.04, help="the paper's ellipse at this f_r")
    p.add_argument("--mission", help="a mission file instead of the ellipse")
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--rate", type=float, default=40.0)
    p.add_argument("--arm", action="store_true", help="arm the vehicle (else wait for a pilot)")
    p.add_argument("--velocity", action="store_true", help="send the reference velocity too")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    mission = (missions.load(args.mission) if args.mission
               else missions.paper_ellipse(args.f_r, args.duration))
    r = follow(args.connect, mission, args.rate, args.arm, args.velocity)
    if args.json:
        print(json.dumps(r))
    else:
        native = "PX4 OFFBOARD" if r["autopilot"] == "px4" else "ArduPilot GUIDED"
        print(f"{native} {r['mode']} following, {r['mission']}: f_cost {r['f_cost']:.3f}, "
              f"steady RMS {r['steady_rms']:.3f} m ({r['samples']} samples)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
