"""The plant's clocks end to end: lockstep holds each telemetry tick until a setpoint answers it,
runs as fast as the two processes go, is deterministic, and falls back to paced time when the
setpoints stop; --speedup runs vehicle time faster than wall time."""

from __future__ import annotations

import math
import time

from sitl_plant.testing import Pilot, PlantProcess, speed_of

LPN, ATT = 32, 30


def newest_pose(pilot: Pilot, after_ms: int, timeout: float = 5.0):
    """The newest LOCAL_POSITION_NED later than ``after_ms`` (older ones are skipped)."""
    msg = pilot.wait("LOCAL_POSITION_NED", timeout, lambda m: m.time_boot_ms > after_ms)
    while (more := pilot.conn.recv_match(type="LOCAL_POSITION_NED", blocking=False)) is not None:
        msg = more if more.time_boot_ms > msg.time_boot_ms else msg
    return msg


def lockstep_session(pilot: Pilot, ticks: int) -> tuple[list[tuple[float, float, float]], float]:
    """Set up, settle with zero setpoints, then answer ``ticks`` telemetry ticks with a
    scripted (speed, turn rate); returns the poses seen and the wall time those ticks took."""
    pilot.wait("HEARTBEAT")
    assert pilot.set_rate(LPN, 20) == 0 and pilot.set_rate(ATT, 20) == 0
    assert pilot.set_mode(15) == 0 and pilot.arm() == 0
    last = -1
    for _ in range(6):                           # zero setpoints: the rover rests at the origin
        last = newest_pose(pilot, last).time_boot_ms
        pilot.speed_turn_rate(0.0, 0.0)
    poses, start = [], time.monotonic()
    for k in range(ticks):
        pose = newest_pose(pilot, last)
        assert pose.time_boot_ms == last + 50    # one tick at a time, none skipped
        last = pose.time_boot_ms
        poses.append((pose.x, pose.y, pose.vx))
        pilot.speed_turn_rate(1.0 + 0.5 * math.sin(0.1 * k), 0.4 * math.cos(0.07 * k))
    return poses, time.monotonic() - start


def test_lockstep_waits_for_each_setpoint_and_runs_fast():
    with PlantProcess("--lockstep", "--lockstep-timeout", "3") as plant, \
            Pilot(plant.port) as pilot:
        poses, wall = lockstep_session(pilot, 60)
        assert wall < 2.0                         # 3 s of vehicle time, much faster than real
        assert math.hypot(poses[-1][0], poses[-1][1]) > 1.0
        last = pilot.wait("LOCAL_POSITION_NED").time_boot_ms   # tick 61, unanswered
        silent = pilot.collect(("LOCAL_POSITION_NED",), 1.0)
        assert silent == []                       # the plant holds the tick
        pilot.speed_turn_rate(1.0, 0.0)
        t0 = time.monotonic()
        nxt = pilot.wait("LOCAL_POSITION_NED", 2.0)
        assert nxt.time_boot_ms == last + 50 and time.monotonic() - t0 < 1.0


def test_lockstep_is_deterministic():
    runs = []
    for _ in range(2):
        with PlantProcess("--lockstep", "--lockstep-timeout", "3") as plant, \
                Pilot(plant.port) as pilot:
            runs.append(lockstep_session(pilot, 40)[0])
    assert runs[0] == runs[1]                     # bit for bit
    assert runs[0][-1] != runs[0][0]


def test_lockstep_falls_back_to_paced_time_when_setpoints_stop():
    with PlantProcess("--lockstep", "--lockstep-timeout", "0.05", "--speedup", "4") as plant, \
            Pilot(plant.port) as pilot:
        lockstep_session(pilot, 10)
        # no more setpoints: each tick waits 0.05 s until 1 s of vehicle time has passed,
        # then the plant runs at 4 x real time again (and the guided timeout still fires)
        pilot.wait("STATUSTEXT", 6.0, lambda m: m.text == "target not received last 3secs, stopping")
        msgs = pilot.collect(("LOCAL_POSITION_NED",), 1.0)
        span = (msgs[-1].time_boot_ms - msgs[0].time_boot_ms) / 1000.0
        assert 2.5 < span < 4.5 and speed_of(msgs[-1]) < 0.01


def test_speedup_runs_vehicle_time_faster_than_wall_time():
    with PlantProcess("--speedup", "5") as plant, Pilot(plant.port) as pilot:
        pilot.wait("HEARTBEAT")
        assert pilot.set_rate(LPN, 20) == 0
        msgs = pilot.collect(("LOCAL_POSITION_NED",), 1.0)
        span = (msgs[-1].time_boot_ms - msgs[0].time_boot_ms) / 1000.0
        assert 3.5 < span < 5.5                   # 5 s nominal; a loaded machine may lag
