"""The baselines a benchmark flies beside the companion's PZC: the autopilot's own trajectory
following (:func:`follow`) and Kanayama's law with gains picked by hand (:func:`kanayama_argv`).

:func:`follow` streams the mission's reference as GUIDED position targets
(SET_POSITION_TARGET_LOCAL_NED, LOCAL_NED, position only, type_mask 3580; ArduPilot's AR_WPNav /
AR_PosControl does the rest) at the telemetry rate, anchored at the rover's start pose exactly as
``companion run`` anchors it, and scores the vehicle's own LOCAL_POSITION_NED. With ``velocity``
the reference velocity goes along as feed-forward (type_mask 3576), which AR_PosControl also
accepts. PX4 (told from the heartbeat): OFFBOARD position targets with the reference velocity as
feed-forward (LOCAL_NED, x, y, vx, vy; type_mask 3556), streamed for a second before OFFBOARD is
asked for (PX4's proof of life), at the rover's current position until armed; PX4 is left in
Hold (AUTO.LOITER) at the end.
"""

from __future__ import annotations

import math
import time
import tomllib

from pymavlink import mavutil

from testbed.process import ROOT
from testbed.scoring import tracking_figures

KANAYAMA_GAINS = ROOT / "benchmarks" / "kanayama_gains.toml"
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
           arm_timeout: float = 120.0, trace: list | None = None) -> dict:
    """The autopilot at ``url`` (ArduPilot or PX4, told from its heartbeat) follows ``mission``
    by its own position control, fed the reference at ``rate`` Hz (module docstring); scored
    from its LOCAL_POSITION_NED (:func:`testbed.scoring.tracking_figures`), left in HOLD.
    ``trace`` (a list) gets (wall s of the sample's arrival, mission s, reference x, y,
    estimate x, y, vehicle s) for each sample, to score against a simulator's truth."""
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
            if trace is not None:
                trace.append((msg._timestamp, t, float(ref.x), float(ref.y), msg.x, msg.y,
                              msg.time_boot_ms / 1000.0))
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
    return {"mission": mission.name, **tracking_figures(errors, mission.duration),
            "autopilot": "px4" if px4 else "ardupilot",
            "mode": "position+velocity" if velocity or px4 else "position"}


def kanayama_argv(frame: str) -> list[str]:
    """``companion run`` arguments flying Kanayama's law with the gains picked by hand for the
    vehicle kind ``frame`` ("skid" or "ackermann", :data:`KANAYAMA_GAINS`): the classical
    baseline issue 20 compares with, not its defaults, which limit-cycle on ArduPilot's rovers.
    The benchmarks that fly it share it."""
    gains = tomllib.loads(KANAYAMA_GAINS.read_text())[frame]
    return ["--controller", "kanayama", "--controller-gains",
            ",".join(f"{name}={float(value):g}" for name, value in gains.items())]
