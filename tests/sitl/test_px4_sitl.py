"""The companion against real PX4: PX4 SITL with SIH and the Ackermann rover
(``10045_sihsim_rover_ackermann``), each test with its own ``px4`` process, ``companion run
--connect udpin:...:14540+N`` as a real process on its offboard link and a ground station (the
pilot) on its GCS link. Skipped unless PX4_SITL or PX4_DIR is set (``testbed/px4.py``);
``make sitl-test`` runs these with the ArduPilot ones.

PX4 runs in real time (SIH at 250 Hz), so a test costs its vehicle seconds in wall seconds; the
companion gets 40 Hz of telemetry. With PX4 the companion sends the velocity vector u_p in
LOCAL_NED (type_mask 3559) and PX4's own rover speed and course loops steer.

The last tests check the harness itself: the skip, the startup files kept off 14550, and that
PX4 is stopped on every way out.
"""

from __future__ import annotations

import csv
import math
import os
import signal
import time
from pathlib import Path

import pytest

import testbed.px4 as harness
from testbed.missions import ellipse_mission
from testbed.px4 import HOLD, OFFBOARD, SKIP_REASON, CompanionProcess, GroundStation
from testbed.safety import read_tlog
from testbed.sitl import ground_speed, process_gone, sent_by_companion, started_by_a_dying_process

BOOT_WALL = 60.0                         # s: PX4 up to armed in OFFBOARD, with margin
CREEP = 0.6                              # m/s: above what PX4's Hold lets the SIH rover creep at
LOCAL_POSITION_NED = 32
MASK_VELOCITY = 3559                     # use vx, vy only: PX4's velocity vector
LOCAL_NED = 1


def _companion(sitl, tmp_path: Path, mission: Path, *extra: str) -> CompanionProcess:
    return CompanionProcess(sitl, "--mission", str(mission), "--arm", "--no-zenoh", "--json",
                            "--log-dir", str(tmp_path / "logs"), *extra)


def _csv_rows(r: dict) -> list[dict]:
    with open(r["csv"], newline="") as f:
        return [row for row in csv.DictReader(f) if row["mission_time"]]


def _well_under_way(gs: GroundStation, seconds: float = 3.0) -> None:
    """Until the ground station has seen the rover armed in OFFBOARD, moving faster than
    0.5 m/s, and ``seconds`` more of vehicle time."""
    gs.wait_for("HEARTBEAT", lambda m: m.custom_mode == OFFBOARD and m.base_mode & 128,
                BOOT_WALL)
    moving = gs.wait_for("LOCAL_POSITION_NED", lambda m: ground_speed(m) > 0.5, 20.0)
    gs.wait_for("LOCAL_POSITION_NED",
                lambda m: m.time_boot_ms >= moving.time_boot_ms + 1000 * seconds, 20.0)


@pytest.mark.px4
@pytest.mark.slow
def test_companion_engages_offboard_arms_tracks_the_ellipse_and_leaves_px4_in_hold(px4, tmp_path):
    """Connect to PX4, stream velocity vectors, OFFBOARD, arm (retried until PX4's heading
    estimate is stable), track 25 s of the paper's ellipse at 0.04 Hz, hand back in Hold, exit
    0; every 40 Hz sample answered."""
    sitl = px4()
    mission = ellipse_mission(tmp_path / "ellipse.toml", duration=25.0, f_r=0.04)
    with _companion(sitl, tmp_path, mission) as comp, GroundStation(sitl) as gs:
        code = comp.wait(BOOT_WALL + 40.0)
        r = comp.result()
        after = gs.wait_for("HEARTBEAT", timeout=5.0)       # the vehicle's own, after the exit
        beats = gs.messages("HEARTBEAT")
    assert code == 0, comp.stderr
    assert r["reason"] == "mission_done" and r["hold_confirmed"], r
    assert r["autopilot"] == "px4" and r["sysid"] == sitl.sysid, r
    assert after.custom_mode == HOLD, hex(after.custom_mode)
    assert any(m.custom_mode == OFFBOARD and m.base_mode & 128 for m in beats)
    assert r["duration_s"] >= 25.0 - 1e-6
    assert r["rate_accepted_hz"] == 40.0
    assert r["loop_rate_hz"] == pytest.approx(40.0, rel=0.03)
    assert r["missed_cycles"] <= 0.01 * r["cycles"], r
    # it went round: the ellipse (6.1 m x 3.6 m half axes) is centred on the start
    rows = _csv_rows(r)
    x0, y0 = float(rows[0]["x"]), float(rows[0]["y"])
    reach = max(math.hypot(float(w["x"]) - x0, float(w["y"]) - y0) for w in rows)
    assert reach > 5.0, reach
    assert r["steady_rms"] < 3.0, r["steady_rms"]
    # what PX4 was sent: velocity vectors in LOCAL_NED, finite and within the speed limit
    frames, bad = read_tlog(Path(r["tlog"]))
    assert bad <= 1
    sps = [m for _, m in sent_by_companion(frames, ("SET_POSITION_TARGET_LOCAL_NED",))]
    assert sps and all(m.coordinate_frame == LOCAL_NED and m.type_mask == MASK_VELOCITY
                       for m in sps)
    assert all(math.isfinite(m.vx) and math.isfinite(m.vy) for m in sps)
    assert max(math.hypot(m.vx, m.vy) for m in sps) <= r["limits"]["max_speed"] + 1e-6
    assert sum(1 for m in sps if m.vx or m.vy) >= 0.98 * 25.0 * 40.0
    print(f"\nPX4 SITL ellipse 0.04 Hz, 25 s: steady RMS {r['steady_rms']:.2f} m, reach "
          f"{reach:.1f} m, {r['cycles']} cycles, missed {r['missed_cycles']}, latency p99 "
          f"{r['latency_p99_ms']:.2f} ms, instance {sitl.instance}")


@pytest.mark.px4
@pytest.mark.slow
def test_sigterm_mid_mission_stops_the_rover_in_hold_and_exits_0(px4, tmp_path):
    sitl = px4()
    mission = ellipse_mission(tmp_path / "ellipse.toml", duration=300.0, f_r=0.04)
    with _companion(sitl, tmp_path, mission) as comp, GroundStation(sitl) as gs:
        _well_under_way(gs)
        t_term = time.monotonic()
        comp.proc.send_signal(signal.SIGTERM)
        code = comp.wait(15.0)
        r = comp.result()
        first = gs.wait_for("LOCAL_POSITION_NED", timeout=5.0, after=t_term)
        t0 = first.time_boot_ms
        # watched for longer than the bound below (it watched 6 s against an 8 s bound, so a
        # stop in 6-8 s, loaded CI, failed as "never slow" instead of being measured)
        watch_ms = 10000
        gs.wait_for("LOCAL_POSITION_NED", lambda m: m.time_boot_ms >= t0 + watch_ms, 25.0,
                    t_term)
        hold = gs.wait_mode(HOLD, timeout=5.0, after=t_term)
        samples = [m for m in gs.messages("LOCAL_POSITION_NED", t_term)
                   if m.time_boot_ms <= t0 + watch_ms]
        hold_after = gs.arrival(hold) - t_term
    assert code == 0, comp.stderr
    assert r["reason"] == "SIGTERM" and r["hold_confirmed"], r
    assert hold.custom_mode == HOLD and hold.base_mode & 128, "Hold, still armed"
    assert ground_speed(first) > 0.3, "the rover was not moving when the companion was stopped"
    # "stopped": below the creep of PX4's own Hold (SIH rover, up to about 0.5 m/s, see below;
    # with 0.2 m/s here, a rover braked from 3.6 to 0.54 m/s in 3 s and then crept at 0.4 was
    # judged stopped only after 7.4 s, and failed a loaded CI run: 2026-12-02)
    slow = [m for m in samples if ground_speed(m) < CREEP]
    assert slow, [round(ground_speed(m), 2) for m in samples]
    stopped_after = (slow[0].time_boot_ms - t0) / 1e3
    # PX4 brakes at RO_DECEL_LIM 3 m/s^2 (about 1 s from 3 m/s) after the zero vectors and Hold;
    # below 0.6 m/s 2.9-3.1 s after the signal in seven runs beside an ArduPilot calibrate
    assert stopped_after <= 8.0, stopped_after
    # what the companion sent last: zero vectors (then PX4's Hold has the rover; the SIH rover
    # creeps in Hold by itself, up to about 0.5 m/s seen: PX4's, not the companion's doing)
    frames, _ = read_tlog(Path(r["tlog"]))
    sps = [m for _, m in sent_by_companion(frames, ("SET_POSITION_TARGET_LOCAL_NED",))]
    last_moving = max(i for i, m in enumerate(sps) if m.vx or m.vy)
    assert last_moving < len(sps) - 1 and all(m.vx == 0 and m.vy == 0
                                               for m in sps[last_moving + 1:])
    print(f"\nSIGTERM at {ground_speed(first):.2f} m/s: below {CREEP} m/s {stopped_after:.2f} s later, "
          f"Hold seen {hold_after:.2f} s after the signal (wall), companion exit {code} after "
          f"{r['wall_s']:.1f} s; speeds over the {watch_ms / 1000:g} s: "
          f"{[round(ground_speed(m), 2) for m in samples[::max(1, len(samples) // 10)]]}")


@pytest.mark.px4
@pytest.mark.slow
def test_a_mode_switch_by_the_ground_station_ends_the_run_with_exit_4_and_no_more_setpoints(
        px4, tmp_path):
    sitl = px4()
    mission = ellipse_mission(tmp_path / "ellipse.toml", duration=300.0, f_r=0.04)
    with _companion(sitl, tmp_path, mission) as comp, GroundStation(sitl) as gs:
        _well_under_way(gs)
        t_switch = time.monotonic()
        assert gs.set_mode(HOLD) == 0
        code = comp.wait(15.0)
        r = comp.result()
        time.sleep(2.0)                              # two more seconds of heartbeats
        modes = {m.custom_mode for m in gs.messages("HEARTBEAT", t_switch + 0.5)}
    assert code == 4, comp.stderr
    assert r["reason"] == "pilot_override: mode changed to LOITER by someone else", r
    assert "pilot took over" in comp.stderr
    assert modes == {HOLD}, [hex(m) for m in modes]      # nobody asked for another mode
    frames, bad = read_tlog(Path(r["tlog"]))
    assert bad <= 1
    msgs = [m for _, m in frames]
    vehicle = (sitl.sysid, 1)
    beats = [(i, m.custom_mode) for i, m in enumerate(msgs) if m.get_type() == "HEARTBEAT"
             and (m.get_srcSystem(), m.get_srcComponent()) == vehicle]
    first_offboard = next(i for i, mode in beats if mode == OFFBOARD)
    seen = next(i for i, mode in beats if i > first_offboard and mode == HOLD)
    sent = sent_by_companion(frames)
    after = [m.get_type() for i, m in sent if i > seen]
    assert after == [], after               # not one setpoint, not one mode request after it
    last_sp = [m for i, m in sent if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"][-1]
    assert last_sp.vx != 0.0 or last_sp.vy != 0.0, "it was tracking, and then silent"
    print(f"\nground station Hold: companion exit {code}; no frame from it after the Hold "
          f"heartbeat; the vehicle stayed in Hold")


@pytest.mark.px4
@pytest.mark.slow
def test_identify_on_px4_flies_the_velocity_vector_manoeuvre_and_fits_the_course_loop(px4,
                                                                                       tmp_path):
    """``companion identify --connect`` on PX4: reads PX4's rover parameters (the priors), flies
    the velocity-vector manoeuvre within --space, leaves PX4 in Hold, and writes a vehicle file
    with PX4's course loop and the Ackermann turning radius (the SIH rover's wheel base 0.321 m
    and 30 deg steering make 0.556 m)."""
    sitl = px4()
    out = tmp_path / "vehicle.toml"
    with CompanionProcess(sitl, "--out", str(out), "--arm", "--space", "8", "--no-zenoh",
                          "--json", "--log-dir", str(tmp_path / "logs"),
                          command="identify") as comp:
        code = comp.wait(BOOT_WALL + 200.0)
    assert code == 0, comp.stderr
    r = comp.result()
    assert r["flight"]["hold_confirmed"] and r["flight"]["max_distance_m"] <= 8.0 + 1.0, r
    assert r["flight"]["duration_s"] < 80.0, r["flight"]     # over with its script (about 60 s)
    assert r["autopilot_params"]["RO_YAW_P"] == 5.0
    assert set(r["params"]) >= {"speed", "turn_rate", "course"}
    from companion.sim.vehicle_file import load
    v = load(out).params
    assert v.velocity_vector and 1.0 <= v.course_gain <= 15.0
    assert 0.556 * 0.7 <= v.min_turn_radius <= 0.556 * 1.8, v.min_turn_radius
    assert r["rms"]["yaw_rate_rad_s"] < 0.5
    print(f"\nPX4 identify: course gain {v.course_gain:.2f} 1/s, turning radius "
          f"{v.min_turn_radius:.3f} m, RMS speed {r['rms']['speed_m_s']:.3f} m/s, turn rate "
          f"{r['rms']['yaw_rate_rad_s']:.3f} rad/s; farthest {r['flight']['max_distance_m']:.1f} m")


# --------------------------------------------------------------------------- the harness itself

def test_without_px4_configured_the_tests_skip_with_the_reason(monkeypatch):
    for name in ("PX4_SITL", "PX4_DIR"):
        monkeypatch.delenv(name, raising=False)
    with pytest.raises(pytest.skip.Exception, match="PX4_SITL") as info:
        harness.px4_paths()
    assert str(info.value.msg) == SKIP_REASON


def test_a_misconfigured_px4_fails_in_one_line(monkeypatch, tmp_path):
    monkeypatch.delenv("PX4_SITL", raising=False)
    monkeypatch.setenv("PX4_DIR", str(tmp_path))
    with pytest.raises(pytest.fail.Exception, match="not an executable px4"):
        harness.px4_paths()
    binary = tmp_path / "bin" / "px4"
    binary.parent.mkdir()
    binary.write_text("#!/bin/sh\n")
    binary.chmod(0o755)
    monkeypatch.setenv("PX4_SITL", str(binary))
    with pytest.raises(pytest.fail.Exception, match="no airframe sihsim_rover_ackermann"):
        harness.px4_paths()


def test_the_startup_files_send_the_gcs_link_to_the_tests_port_not_14550(tmp_path):
    etc = tmp_path / "etc"
    (etc / "init.d-posix").mkdir(parents=True)
    (etc / "init.d-posix" / "px4-rc.mavlink").write_text(
        "udp_gcs_port_local=$((18570+px4_instance))\n"
        "mavlink start -x -u $udp_gcs_port_local -r 4000000 -f\n"
        "mavlink stream -r 50 -s ATTITUDE -u $udp_gcs_port_local\n"
        "mavlink start -x -u $udp_offboard_port_local -r 4000000 -f -m onboard -o 14540\n")
    copy = harness.startup_files(etc, tmp_path / "copy", 40123)
    lines = (copy / "init.d-posix" / "px4-rc.mavlink").read_text().splitlines()
    assert lines[1] == "mavlink start -x -u $udp_gcs_port_local -r 4000000 -f -o 40123"
    assert lines[3].endswith("-m onboard -o 14540")                      # untouched
    assert "-o" not in (etc / "init.d-posix" / "px4-rc.mavlink").read_text().splitlines()[1]


def _gone(pid: int, timeout: float = 8.0) -> bool:
    return process_gone(pid, timeout)


@pytest.mark.px4
def test_instances_side_by_side_and_stopped_on_every_way_out(tmp_path):
    """Two PX4s at once on different ports, each heard on its GCS link with its own system id,
    each with fresh parameters; an exception in the block, the atexit hook and the death of the
    test process each stop the process."""
    pids = []
    with pytest.raises(RuntimeError, match="test failure"):
        with harness.px4_factory(tmp_path / "block") as start:
            a, b = start(), start(params={"RO_SPEED_LIM": 2.5})
            assert a.instance != b.instance
            assert a.ports["offboard_out"] != b.ports["offboard_out"]
            for s in (a, b):
                assert harness.FORBIDDEN_PORT not in s.ports.values()
                with GroundStation(s) as gs:
                    beat = gs.wait_for("HEARTBEAT", timeout=15.0)
                    assert beat.get_srcSystem() == s.sysid
            assert "RO_SPEED_LIM" in b.log_path.read_text()          # PX4 set it
            assert "RO_SPEED_LIM" not in a.log_path.read_text()
            pids = [a.proc.pid, b.proc.pid]
            raise RuntimeError("test failure")
    assert pids and all(_gone(pid) for pid in pids)
    assert not harness._LIVE
    c = harness.PX4SITL(tmp_path / "atexit").start()
    pid = c.proc.pid
    harness._stop_all()
    assert _gone(pid) and not c.alive() and c.lock is None
    orphan = started_by_a_dying_process("testbed.px4", "PX4SITL", tmp_path / "orphan", 60)
    try:
        assert _gone(orphan), f"px4 {orphan} outlived the process that started it"
    finally:
        if not _gone(orphan, 0.0):
            os.kill(orphan, signal.SIGKILL)
