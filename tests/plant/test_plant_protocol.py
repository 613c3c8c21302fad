"""End-to-end protocol tests: a real ``sitl-plant`` process, real loopback UDP, a pymavlink
``udpin`` ground station in the test (sitl_plant.testing). Vehicle time is read from the
telemetry's time_boot_ms, so the assertions hold under --speedup on a loaded machine."""

from __future__ import annotations

import math
import random
import signal
import subprocess
import sys
from itertools import pairwise

import pytest

from sitl_plant.testing import GUIDED, HOLD, MASK_VELOCITY, Pilot, PlantProcess, speed_of

LPN, ATT = 32, 30


def ready(pilot: Pilot, hz: float = 20.0, guided: bool = True, arm: bool = True) -> None:
    pilot.wait("HEARTBEAT")
    assert pilot.set_rate(LPN, hz) == 0 and pilot.set_rate(ATT, hz) == 0
    if guided:
        assert pilot.set_mode(GUIDED) == 0
    if arm:
        assert pilot.arm() == 0


def latest(msgs, kind="LOCAL_POSITION_NED"):
    return [m for m in msgs if m.get_type() == kind][-1]


def test_heartbeat_and_sys_status_fields():
    with PlantProcess("--speedup", "4", sysid=7) as plant, Pilot(plant.port, 7) as pilot:
        hb = pilot.wait("HEARTBEAT")
        assert hb.get_msgbuf()[0] == 0xFD                     # MAVLink 2
        assert (hb.get_srcSystem(), hb.get_srcComponent()) == (7, 1)
        assert hb.type == 10 and hb.autopilot == 3            # GROUND_ROVER, ARDUPILOTMEGA
        assert hb.custom_mode == 0 and hb.base_mode & 1 and not hb.base_mode & 128
        assert hb.system_status == 3                          # STANDBY
        msgs = pilot.collect(("HEARTBEAT", "SYS_STATUS", "ATTITUDE"), 2.0)
        att = [m.time_boot_ms for m in msgs if m.get_type() == "ATTITUDE"]
        beats = sum(m.get_type() == "HEARTBEAT" for m in msgs)
        assert sum(m.get_type() == "SYS_STATUS" for m in msgs) >= 3
        vehicle_seconds = (att[-1] - att[0]) / 1000.0         # default ATTITUDE rate is 1 Hz
        assert len(att) >= 4 and abs(beats - vehicle_seconds) <= 2.0


def test_mode_and_arm_commands_are_acknowledged():
    with PlantProcess("--speedup", "4") as plant, Pilot(plant.port) as pilot:
        pilot.wait("HEARTBEAT")
        assert pilot.set_mode(GUIDED) == 0
        hb = pilot.wait("HEARTBEAT", cond=lambda m: m.custom_mode == GUIDED)
        assert hb.base_mode & 8                                # GUIDED_ENABLED
        assert pilot.arm() == 0
        hb = pilot.wait("HEARTBEAT", cond=lambda m: m.base_mode & 128)
        assert hb.system_status == 4 and hb.custom_mode == GUIDED
        assert pilot.set_mode(2) == 4                          # no mode 2 on a Rover: FAILED
        pilot.mav.set_mode_send(1, 1, HOLD)                    # the older SET_MODE message
        ack = pilot.wait("COMMAND_ACK", cond=lambda m: m.command == 11)
        assert ack.result == 0 and ack.target_system == 255 and ack.target_component == 190
        pilot.wait("HEARTBEAT", cond=lambda m: m.custom_mode == HOLD)
        assert pilot.arm(False) == 0
        pilot.wait("HEARTBEAT", cond=lambda m: not m.base_mode & 128)
        assert pilot.command(31000) == 3                       # unknown command: UNSUPPORTED
        pilot.collect(("STATUSTEXT",), 0.3)
        for text in ("Mode changed to GUIDED", "Throttle armed", "Mode changed to HOLD",
                     "Throttle disarmed"):
            assert text in pilot.texts


def test_arming_refused_during_arm_delay_then_accepted():
    with PlantProcess("--speedup", "4", "--arm-delay", "3") as plant, Pilot(plant.port) as pilot:
        ready(pilot, hz=10, guided=False, arm=False)
        assert pilot.arm() == 1                                # TEMPORARILY_REJECTED
        assert "Arm: AHRS: not using configured AHRS type" in pilot.texts
        refused_at = pilot.wait("ATTITUDE").time_boot_ms
        while pilot.arm() != 0:                                # retry, as a companion must
            refused_at = pilot.wait("ATTITUDE").time_boot_ms
            pilot.collect((), 0.1)
        assert refused_at <= 3100
        assert pilot.wait("ATTITUDE").time_boot_ms >= 3000
        pilot.wait("HEARTBEAT", cond=lambda m: m.base_mode & 128)


def test_message_rates_accepted_refused_disabled_and_default():
    with PlantProcess("--speedup", "4") as plant, Pilot(plant.port) as pilot:
        pilot.wait("HEARTBEAT")
        assert pilot.set_rate(LPN, 40) == 0 and pilot.set_rate(ATT, 40) == 0
        msgs = pilot.collect(("LOCAL_POSITION_NED", "ATTITUDE"), 0.8)
        lpn = [m.time_boot_ms for m in msgs if m.get_type() == "LOCAL_POSITION_NED"]
        rate = (len(lpn) - 1) / ((lpn[-1] - lpn[0]) / 1000.0)
        assert len(lpn) > 60 and rate == pytest.approx(40.0, abs=0.5)
        for before, m in pairwise(msgs):                   # ATTITUDE just before, same time
            if m.get_type() == "LOCAL_POSITION_NED":
                assert before.get_type() == "ATTITUDE" and before.time_boot_ms == m.time_boot_ms
        assert pilot.set_rate(LPN, 50) == 2                    # above 0.8 x loop rate: DENIED
        assert "Requested rate for message ID 32 too fast" in pilot.texts  # sent before the ACK
        lpn = [m.time_boot_ms for m in pilot.collect(("LOCAL_POSITION_NED",), 0.5)]
        assert (len(lpn) - 1) / ((lpn[-1] - lpn[0]) / 1000.0) == pytest.approx(40.0, abs=0.5)
        assert pilot.set_rate(LPN, -1) == 0                    # -1 disables
        msgs = pilot.collect(("LOCAL_POSITION_NED", "ATTITUDE"), 0.3)
        assert msgs and all(m.get_type() == "ATTITUDE" for m in msgs)
        assert pilot.command(511, LPN, 0) == 0                 # 0 restores the default (1 Hz)
        lpn = [m.time_boot_ms for m in pilot.collect(("LOCAL_POSITION_NED",), 1.0)]
        assert 2 <= len(lpn) <= 6 and all(b - a == 1000 for a, b in pairwise(lpn))
        pilot.mav.command_long_send(1, 1, 510, 0, LPN, 0, 0, 0, 0, 0, 0)  # GET_MESSAGE_INTERVAL
        reply = pilot.wait("MESSAGE_INTERVAL")
        assert reply.message_id == LPN and reply.interval_us == 1_000_000
        assert pilot.wait("COMMAND_ACK", cond=lambda m: m.command == 510).result == 0


def test_higher_loop_rate_allows_fifty_hertz():
    with PlantProcess("--speedup", "2", "--loop-rate", "63") as plant, Pilot(plant.port) as pilot:
        pilot.wait("HEARTBEAT")
        assert pilot.set_rate(LPN, 50) == 0
        lpn = [m.time_boot_ms for m in pilot.collect(("LOCAL_POSITION_NED",), 1.0)]
        assert {b - a for a, b in pairwise(lpn)} == {20}


def test_targets_ignored_unless_guided_and_armed():
    with PlantProcess("--speedup", "2") as plant, Pilot(plant.port) as pilot:
        ready(pilot, guided=False, arm=True)                   # MANUAL, armed
        go = lambda: pilot.speed_turn_rate(1.0, 0.2)
        msgs = pilot.stream(go, 0.6)
        assert all(speed_of(m) == 0.0 and m.x == 0.0 for m in msgs)
        assert pilot.arm(False) == 0 and pilot.set_mode(GUIDED) == 0   # GUIDED, disarmed
        msgs = pilot.stream(go, 0.6)
        assert all(speed_of(m) == 0.0 and m.x == 0.0 for m in msgs)
        assert pilot.arm() == 0                                # GUIDED and armed: it drives
        assert speed_of(latest(pilot.stream(go, 0.6))) > 0.9


def test_speed_and_turn_rate_setpoints_drive_the_rover():
    with PlantProcess("--speedup", "2") as plant, Pilot(plant.port) as pilot:
        ready(pilot)
        msgs = pilot.stream(lambda: pilot.speed_turn_rate(1.5, 0.3), 1.5,
                            kinds=("LOCAL_POSITION_NED", "ATTITUDE"))
        pos, att = latest(msgs), latest(msgs, "ATTITUDE")
        assert speed_of(pos) == pytest.approx(1.5, abs=0.01)
        assert att.yawspeed == pytest.approx(0.3, abs=0.005)
        assert -math.pi < att.yaw <= math.pi and att.yaw > 0.3
        heading = math.atan2(pos.vy, pos.vx)                   # d_cen = 0: p moves along yaw
        assert math.cos(heading - att.yaw) > 0.99
        assert math.hypot(pos.x, pos.y) > 1.0
        msgs = pilot.stream(lambda: pilot.speed_turn_rate(-1.0, 0.0), 1.0,
                            kinds=("LOCAL_POSITION_NED", "ATTITUDE"))
        pos, att = latest(msgs), latest(msgs, "ATTITUDE")      # vx < 0 reverses
        along = pos.vx * math.cos(att.yaw) + pos.vy * math.sin(att.yaw)
        assert along == pytest.approx(-1.0, abs=0.02)


def test_guided_timeout_stops_after_three_seconds_and_stays_guided():
    with PlantProcess("--speedup", "4") as plant, Pilot(plant.port) as pilot:
        ready(pilot, hz=20)
        pilot.drain()
        pilot.speed_turn_rate(1.0, 0.0)                        # one target, then silence
        moving = pilot.wait("LOCAL_POSITION_NED", cond=lambda m: speed_of(m) > 0.0)
        before = pilot.collect(("LOCAL_POSITION_NED",), 0.5)
        assert speed_of(before[-1]) == pytest.approx(1.0, abs=1e-3)
        pilot.wait("STATUSTEXT", 3.0, lambda m: m.text == "target not received last 3secs, stopping")
        slowing = pilot.wait("LOCAL_POSITION_NED", cond=lambda m: speed_of(m) < 0.999)
        assert 2.95 <= (slowing.time_boot_ms - moving.time_boot_ms) / 1000.0 <= 3.1
        stopped = pilot.collect(("LOCAL_POSITION_NED", "HEARTBEAT"), 0.5)
        assert speed_of(latest(stopped)) < 0.01
        assert latest(stopped, "HEARTBEAT").custom_mode == GUIDED


def test_velocity_and_position_targets():
    with PlantProcess("--speedup", "4") as plant, Pilot(plant.port) as pilot:
        ready(pilot)
        msgs = pilot.stream(lambda: pilot.setpoint(MASK_VELOCITY, 1, vx=0.0, vy=1.0), 1.0,
                            kinds=("LOCAL_POSITION_NED", "ATTITUDE"))
        assert latest(msgs, "ATTITUDE").yaw == pytest.approx(math.pi / 2, abs=0.02)  # east
        assert latest(msgs).vy == pytest.approx(1.0, abs=0.02)
        pilot.setpoint(3580, 1, x=3.0, y=-2.0)                 # drive to (3, -2), sent once
        pos = pilot.wait("LOCAL_POSITION_NED", 8.0, lambda m: math.hypot(m.x - 3, m.y + 2) < 0.5
                         and speed_of(m) < 0.01)
        assert pos.time_boot_ms > 3000
        assert "target not received last 3secs, stopping" not in pilot.texts


def test_hold_from_another_system_stops_the_rover():
    with PlantProcess("--speedup", "2") as plant, Pilot(plant.port) as pilot:
        ready(pilot)
        assert speed_of(latest(pilot.stream(lambda: pilot.speed_turn_rate(1.0, 0.0), 0.5))) > 0.9
        pilot.mav.srcSystem = 42                               # a second ground station
        pilot.mav.set_mode_send(1, 1, HOLD)
        ack = pilot.wait("COMMAND_ACK", cond=lambda m: m.command == 11)
        assert ack.result == 0 and ack.target_system == 42
        pilot.mav.srcSystem = 255
        msgs = pilot.stream(lambda: pilot.speed_turn_rate(1.0, 0.0), 0.6)  # companion keeps on
        assert speed_of(latest(msgs)) < 0.01
        pilot.wait("HEARTBEAT", cond=lambda m: m.custom_mode == HOLD)


def test_two_plants_side_by_side_ignore_other_system_ids():
    with PlantProcess("--speedup", "2", sysid=1) as p1, PlantProcess("--speedup", "2", sysid=2) as p2, \
            Pilot(p1.port, 1) as one, Pilot(p2.port, 2) as two:
        assert one.wait("HEARTBEAT").get_srcSystem() == 1
        assert two.wait("HEARTBEAT").get_srcSystem() == 2
        ready(one)
        ready(two)
        one.mav.command_long_send(2, 1, 176, 0, 1, HOLD, 0, 0, 0, 0, 0)   # for sysid 2, sent to 1
        drive_other = lambda: one.setpoint(1511, 8, vx=1.0, target_system=2)
        msgs = one.stream(drive_other, 0.6, kinds=("LOCAL_POSITION_NED", "COMMAND_ACK"))
        assert not [m for m in msgs if m.get_type() == "COMMAND_ACK"]
        assert all(speed_of(m) == 0.0 for m in msgs)
        assert speed_of(latest(one.stream(lambda: one.speed_turn_rate(1.0, 0.0), 0.6))) > 0.9
        assert speed_of(latest(two.collect(("LOCAL_POSITION_NED",), 0.3))) == 0.0


def test_garbage_and_non_finite_setpoints_do_not_crash_it():
    with PlantProcess("--speedup", "2") as plant, Pilot(plant.port) as pilot:
        ready(pilot)
        for _ in range(3):                                     # NaN / inf in used fields
            pilot.mav.set_position_target_local_ned_send(0, 1, 1, 8, 1511, 0, 0, 0, math.nan, 0,
                                                         0, 0, 0, 0, 0, math.inf)
        msgs = pilot.collect(("LOCAL_POSITION_NED",), 0.5)
        assert msgs and all(speed_of(m) == 0.0 for m in msgs)
        assert pilot.wait("SYS_STATUS", 3.0).errors_count1 == 3   # counted
        address = next(iter(pilot.conn.clients))
        sock, rng = pilot.conn.port, random.Random(1)
        frame = pilot.mav.command_long_encode(1, 1, 31000, 0, 0, 0, 0, 0, 0, 0, 0).pack(pilot.mav)
        junk = [bytes(rng.randrange(256) for _ in range(rng.randrange(1, 300))) for _ in range(50)]
        junk += [frame[:-3], b"\xfd\xff" + frame[2:], frame[:10] + b"\x00" + frame[11:], b"\xfd",
                 b"\xfe" * 400, b""]
        for blob in junk:
            sock.sendto(blob, address)
        # a corrupt length byte may swallow the next few datagrams (pymavlink parses a byte
        # stream): a companion retries, and so does this pilot
        results = []
        while not results or results[-1] is None:
            assert len(results) < 8, "no answer after garbage"
            try:
                results.append(pilot.command(400, 1.0, timeout=0.5))
            except AssertionError:
                results.append(None)
        assert plant.alive() and results[-1] == 0
        assert pilot.wait("SYS_STATUS", 3.0).errors_comm > 0     # garbage was counted
        assert speed_of(latest(pilot.stream(lambda: pilot.speed_turn_rate(1.0, 0.0), 0.5))) > 0.9
    assert "Traceback" not in plant.stderr


def test_nonsense_command_parameters_are_refused_not_fatal():
    with PlantProcess("--speedup", "2") as plant, Pilot(plant.port) as pilot:
        pilot.wait("HEARTBEAT")
        assert pilot.command(510, 1e30) == 4                   # GET_MESSAGE_INTERVAL, no such id
        assert pilot.command(511, LPN, math.nan) == 4
        assert pilot.command(176, 1, math.nan) == 4            # DO_SET_MODE
        assert pilot.command(176, 0, GUIDED) == 4              # custom-mode flag missing
        assert pilot.command(400, math.nan) == 3               # ARM_DISARM
        assert pilot.command(400, 0.5) == 3
        assert pilot.command(512, 9999) == 2                   # REQUEST_MESSAGE, not ours
        assert pilot.command(512, LPN) == 0
        assert pilot.wait("LOCAL_POSITION_NED") is not None
        assert pilot.set_mode(GUIDED) == 0 and plant.alive()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signals_exit_cleanly(sig):
    with PlantProcess() as plant, Pilot(plant.port) as pilot:
        pilot.wait("HEARTBEAT")
        assert plant.stop(sig) == 0
    assert "stopped at" in plant.stderr and "Traceback" not in plant.stderr


def test_duration_exits_zero_on_vehicle_time():
    run = subprocess.run([sys.executable, "-m", "sitl_plant", "--connect", "udpout:127.0.0.1:9",
                          "--duration", "5", "--speedup", "20"], capture_output=True, text=True,
                         timeout=20)
    assert run.returncode == 0 and "stopped at t=5.000 s" in run.stderr


@pytest.mark.parametrize("args", [
    ["--speedup", "0"], ["--sysid", "300"], ["--preset", "fast"], ["--dropout", "2"],
    ["--start", "1", "2"], ["--w-c", "nan"], ["--connect", "udpin:127.0.0.1:99999"],
    ["--connect", "tcp:127.0.0.1:notaport"], ["--loop-rate", "-50"], ["--bogus"],
])
def test_bad_command_line_is_one_line_and_exit_code_two(args):
    run = subprocess.run([sys.executable, "-m", "sitl_plant", *args], capture_output=True,
                         text=True, timeout=20)
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sitl-plant: error:")
