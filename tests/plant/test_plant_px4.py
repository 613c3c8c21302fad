"""The PX4 personality end to end: heartbeat, OFFBOARD only after proof of life, the rover follows
the velocity vector (yaw rate ignored), and falls back to Hold when the stream stops."""

from __future__ import annotations

import math

import pytest

from sitl_plant.testing import Pilot, PlantProcess, speed_of

OFFBOARD = 6 << 16
HOLD = (4 << 16) | (3 << 24)
MANUAL = 1 << 16
VELOCITY = 3559                # vx, vy used; position, acceleration, yaw, yaw rate ignored


def test_px4_offboard_proof_of_life_velocity_following_and_loss():
    # real time: a stall of the test process longer than 0.5 s would (rightly) end OFFBOARD
    with PlantProcess("--autopilot", "px4") as plant, \
            Pilot(plant.port) as pilot:
        hb = pilot.wait("HEARTBEAT")
        assert hb.autopilot == 12 and hb.type == 10 and hb.custom_mode == MANUAL
        assert pilot.set_rate(32, 20) == 0 and pilot.set_rate(30, 20) == 0
        assert pilot.set_mode(6) == 2                     # no setpoint stream yet: DENIED
        east = lambda: pilot.setpoint(VELOCITY, 1, vx=0.0, vy=1.0, yaw_rate=2.0)
        pilot.stream(east, 1.2, hz=10)                    # proof of life: 1.2 s at 10 Hz
        assert pilot.set_mode(6) == 0
        assert pilot.arm() == 0                           # keep streaming: gaps > 0.5 s end it
        beats = pilot.stream(east, 1.1, hz=10, kinds=("HEARTBEAT",))
        assert beats and all(m.custom_mode == OFFBOARD and m.base_mode & 128 for m in beats)
        msgs = pilot.stream(east, 1.2, hz=10, kinds=("LOCAL_POSITION_NED", "ATTITUDE"))
        pos = [m for m in msgs if m.get_type() == "LOCAL_POSITION_NED"][-1]
        att = [m for m in msgs if m.get_type() == "ATTITUDE"][-1]
        assert att.yaw == pytest.approx(math.pi / 2, abs=0.02)   # heading follows the vector
        assert abs(att.yawspeed) < 0.05                           # yaw_rate 2.0 ignored
        assert pos.vy == pytest.approx(1.0, abs=0.02) and pos.y > 0.5
        # the stream stops: after COM_OF_LOSS_T (0.5 s) it leaves OFFBOARD for Hold
        pilot.wait("STATUSTEXT", 3.0, lambda m: m.text == "Offboard signal lost, switching to Hold")
        pilot.wait("HEARTBEAT", cond=lambda m: m.custom_mode == HOLD and m.base_mode & 128)
        pos = pilot.wait("LOCAL_POSITION_NED", 3.0, lambda m: speed_of(m) < 0.01)
        assert pos.y > 0.5
