"""The companion against the real autopilot: ArduPilot Rover SITL (``rover-skid``), each test
with its own ``ardurover`` process, ``companion run --connect tcp:...`` as a real process on its
SERIAL0 and a ground station (the pilot) on its SERIAL1. Skipped unless ARDUPILOT_SITL or
ARDUPILOT_DIR is set (``testbed/ardupilot.py``); ``make sitl-test`` runs only these.

Time: the vehicle runs at ``SPEEDUP`` x real time (its clock, ``time_boot_ms``, is simulation
time), so the boot to armed (about 46 s of vehicle time: ArduPilot arms in GUIDED only once its
EKF uses GPS, about 42 s after boot; in MANUAL it would arm at about 27 s) and the missions take
a fifth of their vehicle time; the companion then gets SPEEDUP x 40 Hz of telemetry, and the
tests check that it answers every sample. Vehicle-time limits are in vehicle seconds.

The last tests check the harness itself: the skip, and that SITL is stopped on every way out.
"""

from __future__ import annotations

import csv
import math
import os
import signal
import time
from pathlib import Path

import pytest

import testbed.ardupilot as harness
from testbed.ardupilot import GUIDED, HOLD, MANUAL, SKIP_REASON, CompanionProcess, GroundStation, from_vehicle
from testbed.missions import circle_mission
from testbed.safety import read_tlog
from testbed.sitl import ground_speed, process_gone, sent_by_companion, started_by_a_dying_process

SPEEDUP = 5
BOOT_WALL = 120.0 / SPEEDUP + 20.0      # wall s: boot to armed (~40-50 vehicle s) with margin
LOCAL_POSITION_NED = 32
COMPANION = (191,)                      # MAV_COMP_ID_ONBOARD_COMPUTER: the companion's frames


def _companion(sitl, tmp_path: Path, mission: Path, *extra: str) -> CompanionProcess:
    return CompanionProcess(sitl.url(0), "--mission", str(mission), "--arm", "--no-zenoh",
                            "--json", "--log-dir", str(tmp_path / "logs"), *extra)


def _well_under_way(gs: GroundStation, seconds: float = 3.0, timeout: float = BOOT_WALL) -> None:
    """Until the ground station has seen the rover armed in GUIDED, moving faster than 0.5 m/s,
    and ``seconds`` more of vehicle time."""
    gs.wait_for("HEARTBEAT", lambda m: m.custom_mode == GUIDED and m.base_mode & 128, timeout)
    moving = gs.wait_for("LOCAL_POSITION_NED", lambda m: ground_speed(m) > 0.5, 30.0)
    gs.wait_for("LOCAL_POSITION_NED",
                lambda m: m.time_boot_ms >= moving.time_boot_ms + 1000 * seconds, 30.0)


def _csv_rows(r: dict) -> list[dict]:
    with open(r["csv"], newline="") as f:
        return [row for row in csv.DictReader(f) if row["mission_time"]]


def _events(r: dict) -> list[dict]:
    with open(r["csv"], newline="") as f:
        return [row for row in csv.DictReader(f) if row["event"]]


@pytest.mark.sitl
@pytest.mark.slow
def test_companion_arms_tracks_a_circle_and_leaves_the_rover_in_hold(ardupilot, tmp_path):
    """Connect, arm (retried until the EKF is up), track a 6 m circle for 25 s, stop in HOLD,
    exit 0; every one of SPEEDUP x 40 samples a second answered, none missed."""
    sitl = ardupilot(speedup=SPEEDUP)
    mission = circle_mission(tmp_path / "circle.toml", duration=25.0)
    wall0 = time.monotonic()
    with _companion(sitl, tmp_path, mission) as comp, GroundStation(sitl) as gs:
        code = comp.wait(BOOT_WALL + 60.0)
        wall = time.monotonic() - wall0
        r = comp.result()
        after = gs.wait_for("HEARTBEAT", timeout=5.0)       # the vehicle's own, after the exit
        guided = gs.messages("HEARTBEAT")
    assert code == 0, comp.stderr
    assert r["reason"] == "mission_done" and r["hold_confirmed"], r
    assert after.custom_mode == HOLD, after
    assert after.base_mode & 128, "HOLD, still armed: the companion stops, it does not disarm"
    assert any(m.custom_mode == GUIDED and m.base_mode & 128 for m in guided)
    assert r["autopilot"] == "ardupilot" and r["rate_accepted_hz"] == 40.0
    assert r["duration_s"] >= 25.0 - 1e-6
    # it tracked: round the circle (6 m across), on it
    rows = _csv_rows(r)
    x0, y0 = float(rows[0]["x"]), float(rows[0]["y"])
    reach = max(math.hypot(float(w["x"]) - x0, float(w["y"]) - y0) for w in rows)
    assert reach > 5.0, reach
    assert r["steady_rms"] < 0.3, r["steady_rms"]
    # it kept up: 40 Hz of vehicle time, every sample answered, at most 1 % missed
    assert r["loop_rate_hz"] == pytest.approx(40.0, rel=0.02)
    assert r["cycles"] >= 0.98 * 25.0 * 40.0, r["cycles"]
    assert r["missed_cycles"] <= 0.01 * r["cycles"], r
    assert r["setpoints_sent"] >= r["telemetry_received"] - 2, r
    frames, bad = read_tlog(Path(r["tlog"]))
    assert bad <= 1
    tracking = [(ts, m) for ts, m in frames if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
                and m.get_srcComponent() in COMPANION and (m.vx or m.yaw_rate)]
    span_wall = tracking[-1][0] - tracking[0][0]
    span_vehicle = (tracking[-1][1].time_boot_ms - tracking[0][1].time_boot_ms) / 1e3
    achieved = span_vehicle / span_wall
    assert len(tracking) / span_wall == pytest.approx(40.0 * achieved, rel=0.05)
    assert r["latency_p99_ms"] < 25.0 / SPEEDUP, r["latency_p99_ms"]
    tracking_from = next(float(row["vehicle_time"]) for row in _events(r)
                         if row["event"].startswith("tracking"))
    print(f"\nSITL circle: armed and tracking at vehicle time {tracking_from:.1f} s; "
          f"wall {wall:.1f} s (companion {r['wall_s']:.1f} s), vehicle speedup "
          f"{achieved:.2f} while tracking, {len(tracking) / span_wall:.0f} setpoints per wall "
          f"second, {r['cycles']} cycles, missed {r['missed_cycles']} (overruns "
          f"{r['overruns']}), latency p99 {r['latency_p99_ms']:.2f} ms, steady RMS "
          f"{r['steady_rms']:.3f} m, f_cost {r['f_cost']:.2f}, SITL CPU "
          f"{sitl.cpu_seconds():.1f} s")


@pytest.mark.sitl
@pytest.mark.slow
def test_sigterm_mid_mission_stops_the_rover_in_hold_and_exits_0(ardupilot, tmp_path):
    sitl = ardupilot(speedup=SPEEDUP)
    mission = circle_mission(tmp_path / "circle.toml", duration=300.0)
    with _companion(sitl, tmp_path, mission) as comp, GroundStation(sitl) as gs:
        assert gs.set_rate(LOCAL_POSITION_NED, 10.0) == 0
        _well_under_way(gs)
        t_term = time.monotonic()
        comp.proc.send_signal(signal.SIGTERM)
        code = comp.wait(15.0)
        r = comp.result()
        first = gs.wait_for("LOCAL_POSITION_NED", timeout=5.0, after=t_term)
        t0 = first.time_boot_ms
        gs.wait_for("LOCAL_POSITION_NED", lambda m: m.time_boot_ms >= t0 + 6000, 30.0, t_term)
        hold = gs.wait_mode(HOLD, timeout=5.0, after=t_term)
        samples = [m for m in gs.messages("LOCAL_POSITION_NED", t_term)
                   if m.time_boot_ms <= t0 + 6000]
    assert code == 0, comp.stderr
    assert r["reason"] == "SIGTERM" and r["hold_confirmed"], r
    assert hold.custom_mode == HOLD
    assert ground_speed(first) > 0.3, "the rover was not moving when the companion was stopped"
    slow = [m for m in samples if ground_speed(m) < 0.2]
    assert slow, [round(ground_speed(m), 2) for m in samples]
    stopped_after = (slow[0].time_boot_ms - t0) / 1e3
    assert stopped_after <= 3.0, stopped_after
    still = [round(ground_speed(m), 3) for m in samples if m.time_boot_ms >= slow[0].time_boot_ms]
    assert max(still) < 0.2, still
    print(f"\nSIGTERM at {ground_speed(first):.2f} m/s: below 0.2 m/s {stopped_after:.2f} s "
          f"(vehicle) later, HOLD, companion exit {code} after {r['wall_s']:.1f} s")


@pytest.mark.sitl
@pytest.mark.slow
def test_pilot_switching_to_manual_ends_the_run_with_exit_4_and_no_more_setpoints(ardupilot,
                                                                                   tmp_path):
    sitl = ardupilot(speedup=SPEEDUP)
    mission = circle_mission(tmp_path / "circle.toml", duration=300.0)
    with _companion(sitl, tmp_path, mission) as comp, GroundStation(sitl) as gs:
        assert gs.set_rate(LOCAL_POSITION_NED, 10.0) == 0
        _well_under_way(gs)
        t_switch = time.monotonic()
        switched_at = gs.messages("LOCAL_POSITION_NED")[-1].time_boot_ms   # vehicle ms, +-0.1 s
        assert gs.set_mode(MANUAL) == 0
        t_ack = time.monotonic()
        code = comp.wait(15.0)
        r = comp.result()
        time.sleep(2.0)                          # ten vehicle seconds of heartbeats after it
        # Heartbeats from after the ACK: one that left before the switch took effect may
        # still arrive after the request (seen once: GUIDED, then MANUAL ever after).
        modes = [m.custom_mode for m in gs.messages("HEARTBEAT", t_ack)]
        t_beat = next(w for w, m in gs.seen if w >= t_switch and m.get_type() == "HEARTBEAT"
                      and from_vehicle(m) and m.custom_mode == MANUAL)
    assert code == 4, comp.stderr
    assert r["reason"] == "pilot_override: mode changed to MANUAL by someone else", r
    assert "pilot took over" in comp.stderr
    assert modes and set(modes) == {MANUAL}, modes      # nobody asked for another mode
    frames, bad = read_tlog(Path(r["tlog"]))
    assert bad <= 1
    msgs = [m for _, m in frames]
    # the vehicle's heartbeats as the companion received them: GUIDED, then the pilot's MANUAL
    beats = [(i, m.custom_mode) for i, m in enumerate(msgs)
             if m.get_type() == "HEARTBEAT" and from_vehicle(m)]
    first_guided = next(i for i, mode in beats if mode == GUIDED)
    seen = next(i for i, mode in beats if i > first_guided and mode == MANUAL)
    sent = sent_by_companion(frames)
    after = [m.get_type() for i, m in sent if i > seen]
    assert after == [], after                 # not one setpoint, not one mode request after it
    last_sp = [m for i, m in sent if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"][-1]
    assert last_sp.vx != 0.0 or last_sp.yaw_rate != 0.0, "it was tracking, and then silent"
    last_sample = [m for m in msgs[:seen] if m.get_type() == "LOCAL_POSITION_NED"
                   and from_vehicle(m)][-1]
    assert last_sp.time_boot_ms == last_sample.time_boot_ms   # answered up to the news
    unknowing = [m for i, m in sent if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
                 and m.time_boot_ms > switched_at]
    print(f"\npilot MANUAL: ACK after {1e3 * (t_ack - t_switch):.0f} ms, the MANUAL heartbeat "
          f"{1e3 * (t_beat - t_switch):.0f} ms (wall) after the request; about {len(unknowing)} "
          f"setpoints went out in between (the companion cannot know before the heartbeat), "
          f"none after it; the last answered sample {last_sp.time_boot_ms} ms; companion exit "
          f"{code}; the vehicle stayed in MANUAL ({len(modes)} heartbeats)")


@pytest.mark.sitl
@pytest.mark.slow
def test_a_stop_while_waiting_for_the_pilot_leaves_the_armed_rover_in_manual(ardupilot,
                                                                            tmp_path):
    """--start-on-guided: the pilot has armed the rover in MANUAL and drives it; the companion
    waits for the pilot's GUIDED and is stopped (SIGTERM) before that. It has asked nothing of
    the vehicle, so it sends nothing on the way out: no HOLD (which would stop the rover under
    the pilot), no disarm. The vehicle stays armed in MANUAL, as the pilot left it."""
    sitl = ardupilot(speedup=SPEEDUP)
    mission = circle_mission(tmp_path / "circle.toml", duration=60.0)
    with CompanionProcess(sitl.url(0), "--mission", str(mission), "--start-on-guided",
                          "--no-zenoh", "--json", "--log-dir", str(tmp_path / "logs")) as comp, \
            GroundStation(sitl) as gs:
        comp.wait_for_stderr("waiting for the pilot", BOOT_WALL)
        assert gs.set_mode(MANUAL) == 0
        deadline = time.monotonic() + BOOT_WALL            # the pilot arms once prearm passes
        while gs.command(400, 1) != 0:
            assert time.monotonic() < deadline, "SITL would not arm in MANUAL"
            time.sleep(1.0)
        gs.wait_for("HEARTBEAT", lambda m: m.custom_mode == MANUAL and m.base_mode & 128, 10.0)
        t_term = time.monotonic()
        comp.proc.send_signal(signal.SIGTERM)
        code = comp.wait(15.0)
        r = comp.result()
        time.sleep(2.0)                                    # ten vehicle seconds of heartbeats
        beats = [(m.custom_mode, bool(m.base_mode & 128)) for m in gs.messages("HEARTBEAT",
                                                                               t_term)]
    assert code == 0 and (r["reason"], r["stop_cause"]) == ("SIGTERM", "ok"), (r, comp.stderr)
    frames, _ = read_tlog(Path(r["tlog"]))
    asked = [(m.command, m.param1, m.param2) for _, m in sent_by_companion(frames)
             if m.get_type() == "COMMAND_LONG" and m.command in (176, 400)]
    assert asked == [], asked                              # no mode request, no (dis)arming
    assert len(beats) >= 5 and set(beats) == {(MANUAL, True)}, beats
    assert "nothing had been asked of the vehicle: left as it was, in MANUAL" in comp.stderr
    print(f"\nSIGTERM while waiting for the pilot: companion exit {code}, nothing sent; the "
          f"rover stayed armed in MANUAL ({len(beats)} heartbeats after)")


@pytest.mark.sitl
@pytest.mark.slow
def test_rate_50_falls_back_to_40_on_a_stock_rover_and_is_accepted_at_a_100_hz_loop(ardupilot,
                                                                                    tmp_path):
    """ArduPilot refuses message rates above 0.8 x SCHED_LOOP_RATE (50 Hz on Rover): --rate 50
    runs at 40 Hz. The same request on a vehicle with SCHED_LOOP_RATE 100 runs at 50 Hz: two
    SITL instances side by side."""
    stock = ardupilot(speedup=SPEEDUP)
    fast = ardupilot(speedup=SPEEDUP, params={"SCHED_LOOP_RATE": 100})
    assert stock.instance != fast.instance
    mission = circle_mission(tmp_path / "circle.toml", duration=5.0)
    with _companion(stock, tmp_path / "stock", mission, "--rate", "50") as a, \
            _companion(fast, tmp_path / "fast", mission, "--rate", "50") as b:
        codes = a.wait(BOOT_WALL + 30.0), b.wait(BOOT_WALL + 30.0)
        ra, rb = a.result(), b.result()
    assert codes == (0, 0), (a.stderr, b.stderr)
    assert ra["rate_requested_hz"] == 50.0 and ra["rate_accepted_hz"] == 40.0, ra
    assert "vehicle refused 50 Hz telemetry" in a.stderr
    assert ra["loop_rate_hz"] == pytest.approx(40.0, rel=0.02)
    assert rb["rate_requested_hz"] == 50.0 and rb["rate_accepted_hz"] == 50.0, rb
    assert rb["loop_rate_hz"] == pytest.approx(50.0, rel=0.02)
    assert ra["missed_cycles"] <= 0.01 * ra["cycles"] + 1, ra
    assert rb["missed_cycles"] <= 0.01 * rb["cycles"] + 1, rb
    print(f"\n--rate 50: stock rover accepted {ra['rate_accepted_hz']:g} Hz (loop "
          f"{ra['loop_rate_hz']:.2f} Hz, missed {ra['missed_cycles']}), SCHED_LOOP_RATE 100 "
          f"accepted {rb['rate_accepted_hz']:g} Hz (loop {rb['loop_rate_hz']:.2f} Hz, missed "
          f"{rb['missed_cycles']}); instances {stock.instance} and {fast.instance}")


# --------------------------------------------------------------------------- the harness itself

def test_without_sitl_configured_the_tests_skip_with_the_reason(monkeypatch):
    for name in ("ARDUPILOT_SITL", "ARDUPILOT_DIR", "ARDUPILOT_DEFAULTS"):
        monkeypatch.delenv(name, raising=False)
    with pytest.raises(pytest.skip.Exception, match="ARDUPILOT_SITL") as info:
        harness.sitl_paths()
    assert str(info.value.msg) == SKIP_REASON


def test_a_misconfigured_sitl_fails_in_one_line(monkeypatch, tmp_path):
    monkeypatch.delenv("ARDUPILOT_SITL", raising=False)
    monkeypatch.setenv("ARDUPILOT_DIR", str(tmp_path))
    with pytest.raises(pytest.fail.Exception, match="not an executable ardurover"):
        harness.sitl_paths()
    binary = tmp_path / "ardurover"
    binary.write_text("#!/bin/sh\n")
    binary.chmod(0o755)
    monkeypatch.setenv("ARDUPILOT_SITL", str(binary))
    monkeypatch.setenv("ARDUPILOT_DEFAULTS", str(tmp_path / "nope.parm"))
    with pytest.raises(pytest.fail.Exception, match="nope.parm"):
        harness.sitl_paths()


def _gone(pid: int, timeout: float = 5.0) -> bool:
    return process_gone(pid, timeout)


@pytest.mark.sitl
def test_instances_side_by_side_and_stopped_on_every_way_out(tmp_path):
    """Two SITLs at once on different ports, each answering on its SERIAL0; an exception in the
    block, the atexit hook and the death of the test process each stop the process."""
    pids = []
    with pytest.raises(RuntimeError, match="test failure"):
        with harness.sitl_factory(tmp_path / "block") as start:
            a, b = start(speedup=SPEEDUP), start(speedup=SPEEDUP, params={"SYSID_THISMAV": 1})
            assert a.instance != b.instance and a.ports["serial0"] != b.ports["serial0"]
            assert harness.FORBIDDEN_PORT not in {*a.ports.values(), *b.ports.values()}
            assert "SYSID_THISMAV 1" in (b.workdir / "extra.parm").read_text()
            for sitl in (a, b):
                with GroundStation(sitl, serial=0) as gs:
                    gs.wait_for("HEARTBEAT", timeout=10.0)
            pids = [a.proc.pid, b.proc.pid]
            raise RuntimeError("test failure")
    assert pids and all(_gone(pid) for pid in pids)
    assert not harness._LIVE
    # the atexit safety net
    c = harness.ArduPilotSITL(tmp_path / "atexit", speedup=SPEEDUP).start()
    pid = c.proc.pid
    harness._stop_all()
    assert _gone(pid) and not c.alive() and c.lock is None
    # the test process dies without running any of that: SITL gets SIGTERM from the kernel
    orphan = started_by_a_dying_process("testbed.ardupilot", "ArduPilotSITL",
                                        tmp_path / "orphan", 30)
    try:
        assert _gone(orphan), f"ardurover {orphan} outlived the process that started it"
    finally:
        if not _gone(orphan, 0.0):
            os.kill(orphan, signal.SIGKILL)
