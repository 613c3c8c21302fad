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
import math
import os
import sys
import time
from itertools import pairwise
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ["MAVLINK20"] = "1"

from pymavlink import mavutil  # noqa: E402

from companion import mission as missions  # noqa: E402

MASK_POSITION = 3580
MASK_POSITION_VELOCITY = 3576
MASK_PX4_POSITION_VELOCITY = 3556       # x, y, vx, vy (ignore z, vz, acceleration, yaw, yaw rate)
GUIDED, HOLD = 15, 4
PX4_OFFBOARD, PX4_HOLD = (6, 0), (4, 3)  # PX4 (main, sub) modes
MAV_AUTOPILOT_PX4 = 12


def _wait_armable(conn, timeout: float, arm: bool) -> None:
    """GUIDED, then arm (retrying while the EKF settles), or wait for a pilot to arm."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        conn.mav.command_long_send(conn.target_system, conn.target_component, 176, 0, 1, GUIDED,
                                   0, 0, 0, 0, 0)
        if arm:
            conn.mav.command_long_send(conn.target_system, conn.target_component, 400, 0, 1, 0, 0,
                                       0, 0, 0, 0)
        hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=1.0)
        if hb is not None and hb.custom_mode == GUIDED and \
                hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED:
            return
    raise SystemExit("native_follow: the vehicle did not arm in GUIDED")


def _px4_offboard_armed(conn, timeout: float, arm: bool) -> None:
    """Position setpoints at the rover's own position (it stays put) from the start, OFFBOARD
    once they have streamed for over a second, then arm (retrying while PX4's estimator
    settles), or wait for a pilot to arm."""
    t0 = time.monotonic()
    deadline, next_ask = t0 + timeout, t0 + 1.2
    while time.monotonic() < deadline:
        pose = conn.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=1.0)
        if pose is None:
            continue
        conn.mav.set_position_target_local_ned_send(
            pose.time_boot_ms, conn.target_system, conn.target_component, 1,
            MASK_PX4_POSITION_VELOCITY, pose.x, pose.y, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            0.0)
        hb = conn.messages.get("HEARTBEAT")
        if (hb is not None and hb.custom_mode == PX4_OFFBOARD[0] << 16
                and hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED):
            return
        if time.monotonic() >= next_ask:
            next_ask = time.monotonic() + 1.0
            conn.mav.command_long_send(conn.target_system, conn.target_component, 176, 0, 1,
                                       *PX4_OFFBOARD, 0, 0, 0, 0)
            if arm:
                conn.mav.command_long_send(conn.target_system, conn.target_component, 400, 0, 1,
                                           0, 0, 0, 0, 0, 0)
    raise SystemExit("native_follow: PX4 did not arm in OFFBOARD")


def follow(url: str, mission, rate: float = 40.0, arm: bool = True, velocity: bool = False,
           arm_timeout: float = 120.0) -> dict:
    conn = mavutil.mavlink_connection(url, source_system=254, source_component=191,
                                      dialect="ardupilotmega")
    try:
        hb = conn.wait_heartbeat(timeout=30)
        if hb is None:
            raise SystemExit(f"native_follow: no heartbeat on {url}")
        px4 = hb.autopilot == MAV_AUTOPILOT_PX4
        for msg_id in (32, 30):
            conn.mav.command_long_send(conn.target_system, conn.target_component, 511, 0, msg_id,
                                       1e6 / rate, 0, 0, 0, 0, 0)
        if px4:
            _px4_offboard_armed(conn, arm_timeout, arm)
        else:
            _wait_armable(conn, arm_timeout, arm)
        pose = conn.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=5)
        att = conn.recv_match(type="ATTITUDE", blocking=True, timeout=5)
        traj = mission.anchored(pose.x, pose.y, att.yaw)
        t0 = pose.time_boot_ms / 1000.0
        errors, last_ms = [], pose.time_boot_ms
        mask = MASK_POSITION_VELOCITY if velocity else MASK_POSITION
        if px4:
            mask = MASK_PX4_POSITION_VELOCITY
        while True:
            msg = conn.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=2)
            if msg is None:
                raise SystemExit("native_follow: telemetry lost")
            if msg.time_boot_ms <= last_ms:
                continue
            last_ms = msg.time_boot_ms
            t = msg.time_boot_ms / 1000.0 - t0
            if t > mission.duration:
                break
            ref = traj.sample(t)
            errors.append((t, math.hypot(ref.x - msg.x, ref.y - msg.y)))
            ahead = traj.sample(t + 1.0 / rate)
            conn.mav.set_position_target_local_ned_send(
                0, conn.target_system, conn.target_component, 1, mask,
                float(ahead.x), float(ahead.y), 0.0, float(ahead.vx), float(ahead.vy), 0.0,
                0.0, 0.0, 0.0, 0.0, 0.0)
        if px4:
            conn.mav.command_long_send(conn.target_system, conn.target_component, 176, 0, 1,
                                       *PX4_HOLD, 0, 0, 0, 0)
        else:
            conn.mav.command_long_send(conn.target_system, conn.target_component, 176, 0, 1,
                                       HOLD, 0, 0, 0, 0, 0)
    finally:
        conn.close()
    cost = math.sqrt(sum(0.5 * (a ** 2 + b ** 2) * (tb - ta)
                         for (ta, a), (tb, b) in pairwise(errors)))
    steady = [e for t, e in errors if t >= mission.duration / 2]
    return {"mission": mission.name, "f_cost": cost, "samples": len(errors),
            "steady_rms": math.sqrt(sum(e * e for e in steady) / len(steady)),
            "autopilot": "px4" if px4 else "ardupilot",
            "mode": "position+velocity" if velocity or px4 else "position"}


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
