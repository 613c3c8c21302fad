"""The companion stops the rover itself: stale telemetry, SIGTERM, bad telemetry, a rebooted
vehicle, a controller output that is not finite. Real processes, real UDP on loopback."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time

import pytest

from sitl_plant.testing import PlantProcess, free_udp_port
from testbed.fake_vehicle import FakeVehicle, finite_setpoint, is_mode_command, is_zero
from testbed.missions import ellipse_mission
from testbed.process import ROOT, Companion
from testbed.udp_proxy import Proxy

HOLD, GUIDED = 4, 15


def _tracking(proxy: Proxy) -> bool:
    return sum(1 for s in proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")
               if not is_zero(s.msg)) >= 20


def test_stale_telemetry_stops_the_rover_then_resumes(tmp_path):
    """SIGSTOP the plant mid-mission: within 0.6 s of the last telemetry the companion sends a
    zero setpoint and HOLD; after SIGCONT it re-engages GUIDED and finishes the mission."""
    mission = ellipse_mission(tmp_path / "m.toml", 8.0)
    with Proxy() as proxy, \
            PlantProcess("--speedup", "2", "--d-cen", "0.3", port=proxy.plant_port) as plant, \
            Companion(proxy.companion_port, "--arm", "--json", "--mission", str(mission),
                      "--log-dir", str(tmp_path / "logs")) as comp:
        comp.wait_until(lambda: _tracking(proxy), 20.0, "tracking")
        os.kill(plant.proc.pid, signal.SIGSTOP)
        try:
            time.sleep(1.5)
            last = proxy.plant_sent("LOCAL_POSITION_NED")[-1]
            last_tel = last.wall
            # What went out after the last sample: answers to samples sent before it (a loaded
            # companion answers late), then the failsafe's zero setpoint, then only zeros.
            after = proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED", after=last_tel)
            zeros = [k for k, s in enumerate(after) if is_zero(s.msg)]
            assert zeros, "no zero setpoint after telemetry stopped"
            first = after[zeros[0]]
            assert all(s.msg.time_boot_ms <= last.msg.time_boot_ms
                       for s in after[:zeros[0]]), "a moving setpoint answered no sample"
            assert first.wall - last_tel <= 0.6, first.wall - last_tel
            assert all(is_zero(s.msg) for s in after[zeros[0]:]), "moved again in the silence"
            holds = [s for s in proxy.companion_sent("COMMAND_LONG", after=last_tel)
                     if is_mode_command(s.msg, HOLD)]
            assert holds and holds[0].wall >= first.wall
        finally:
            os.kill(plant.proc.pid, signal.SIGCONT)
        resumed_at = time.monotonic()
        assert comp.wait(60.0) == 0, comp.stderr
        r = comp.result()
    assert r["reason"] == "mission_done" and r["failsafes"] == 1
    assert r["duration_s"] >= 8.0 - 1e-6
    guided = [s for s in proxy.companion_sent("COMMAND_LONG", after=resumed_at)
              if is_mode_command(s.msg, GUIDED)]
    assert guided, "did not ask for GUIDED again"
    moving = [s for s in proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED", after=resumed_at)
              if not is_zero(s.msg)]
    assert len(moving) > 20 and moving[0].wall >= guided[0].wall
    assert "filter and integrators reset" in comp.stderr
    # The .tlog alone (no reference in it) gives the live metrics: `companion plot` replays the
    # mission clock, which stood still through the failsafe.
    p = subprocess.run([sys.executable, "-m", "companion", "plot", r["tlog"], "--mission",
                        str(mission), "--out", str(tmp_path / "plot"), "--json"],
                       capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert p.returncode == 0, p.stderr
    m = json.loads(p.stdout)
    assert m["f_cost"] == pytest.approx(r["f_cost"], rel=1e-3)
    assert m["steady_rms"] == pytest.approx(r["steady_rms"], rel=2e-2)


def test_sigterm_stops_the_rover_holds_and_exits_0(tmp_path):
    with Proxy() as proxy, \
            PlantProcess("--speedup", "2", "--d-cen", "0.3", port=proxy.plant_port), \
            Companion(proxy.companion_port, "--arm", "--json", "--mission",
                      "missions/paper_ellipse_012.toml") as comp:
        comp.wait_until(lambda: _tracking(proxy), 20.0, "tracking")
        t_term = time.monotonic()
        comp.proc.send_signal(signal.SIGTERM)
        assert comp.wait(10.0) == 0, comp.stderr
        r = comp.result()
        time.sleep(1.2)    # a plant heartbeat (1 Hz) after the companion left
        heartbeats = proxy.plant_sent("HEARTBEAT", after=time.monotonic() - 1.1)
    assert r["reason"] == "SIGTERM" and r["exit_code"] == 0 and r["hold_confirmed"]
    sps = proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")
    last_moving = max(i for i, s in enumerate(sps) if not is_zero(s.msg))
    assert last_moving < len(sps) - 1 and is_zero(sps[-1].msg)
    holds = [s for s in proxy.companion_sent("COMMAND_LONG", after=t_term)
             if is_mode_command(s.msg, HOLD)]
    assert holds and holds[0].wall >= sps[last_moving + 1].wall
    assert heartbeats and heartbeats[-1].msg.custom_mode == HOLD


def _tracked_from(fake: FakeVehicle, at: list[int], k: int) -> int | None:
    """Tick ``k`` counted from the first tick the companion tracked (``at`` remembers it), or
    None before. Not from the first tick streamed: the setup's waits read (and drop) the stream
    unchecked, and the setup's length varies (a fresh clone's cold bytecode: the first setpoint
    came at tick 40-170, where fixed ticks 60-80 fell into the setup)."""
    if not at and any(not is_zero(sp) for sp in fake.setpoints):
        at.append(k)
    return k - at[0] if at else None


def _bad_telemetry(i: int, ms: int):
    """Bad samples, ``i`` ticks after the companion's first tracking setpoint."""
    script = {
        10: {"x": math.nan, "note": "nan x"},
        14: {"vx": math.inf, "note": "inf vx"},
        18: {"yaw": math.nan, "note": "nan yaw"},
        22: {"sysid": 2, "ms": ms + 1, "note": "other system"},
        26: {"ms": ms - 40, "note": "backwards"},      # before the previous tick, off its grid
        30: {"ms": ms - 25, "note": "duplicate"},
    }
    return script.get(i)


def test_bad_telemetry_never_produces_a_setpoint(tmp_path):
    mission = ellipse_mission(tmp_path / "m.toml", 4.0)
    at: list[int] = []     # the tick the bad samples count from: once tracking setpoints come

    def script(k, ms):
        # (at fixed ticks 60-80 a fresh clone's slow setup dropped some: not_finite 0-2 of 3)
        i = _tracked_from(fake, at, k)
        return _bad_telemetry(i, ms) if i is not None else None

    port = free_udp_port()
    # The fake vehicle is a thread of this test's process, which shares two cores with the
    # suite: a stall of it longer than the default 0.5 s would be a true stale failsafe. The
    # refused samples leave gaps of at most two ticks (50 ms); 2 s tells the two apart.
    fake = FakeVehicle(port, script=script)     # bound before its thread runs the script
    with Companion(port, "--arm", "--json", "--mission", str(mission),
                   "--stale-timeout", "2") as comp, fake:
        assert comp.wait(30.0) == 0, comp.stderr
        r = comp.result()
    assert at, "never tracked"
    bad = {ms: note for ms, note in fake.sent_ms if note and note != "duplicate"}
    assert len(bad) == 5
    for ms, note in bad.items():
        assert fake.answered(ms) == 0, f"a setpoint answered the {note} sample"
    dup = next(ms for ms, note in fake.sent_ms if note == "duplicate")
    assert fake.answered(dup) == 1    # the original sample only
    assert all(finite_setpoint(sp) for sp in fake.setpoints)
    rej = r["telemetry_rejected"]
    assert rej["not_finite"] == 3 and rej["no_attitude"] == 1   # NaN yaw: its position too
    assert rej["other_source"] == 2                              # its ATTITUDE and position
    assert rej["time_backwards"] == 1 and rej["duplicate"] == 1
    assert r["reason"] == "mission_done" and r["failsafes"] == 0, comp.stderr


def test_the_companions_own_stall_is_not_taken_for_stale_telemetry(tmp_path):
    """SIGSTOP the companion (not the vehicle) for twice its stale timeout mid-mission, as an
    overloaded board deschedules it: the vehicle streamed all along and the samples wait in the
    socket, so on waking the companion reads them and goes on (no failsafe), and says it was
    not running. (A 1 s timeout, not 0.5: the fake vehicle is a thread of this loaded process.)"""
    mission = ellipse_mission(tmp_path / "m.toml", 6.0)
    port = free_udp_port()
    with Companion(port, "--arm", "--json", "--mission", str(mission),
                   "--stale-timeout", "1") as comp, \
            FakeVehicle(port) as fake:
        comp.wait_until(lambda: len(fake.setpoints) > 40, 20.0, "tracking")
        os.kill(comp.proc.pid, signal.SIGSTOP)
        try:
            time.sleep(2.0)
            streamed = len(fake.sent_ms)
        finally:
            os.kill(comp.proc.pid, signal.SIGCONT)
        assert comp.wait(30.0) == 0, comp.stderr
        r = comp.result()
    assert streamed > 0
    assert r["reason"] == "mission_done" and r["failsafes"] == 0, (r["reason"], comp.stderr)
    assert "the companion was not running for" in comp.stderr
    assert r["stalls"] >= 1


def test_the_first_pose_sample_goes_with_the_attitude_heard_during_the_setup(tmp_path):
    """The setup (rate negotiation, parameters) reads the vehicle's streams while it waits for
    answers; the loop's first pose sample goes with the ATTITUDE read there, so none is refused
    for want of one. The vehicle sends ATTITUDE every 16th tick (0.4 s: within the 0.5 s an
    attitude serves), so before the change the samples until the next one were refused
    ("no_attitude"; the lockstep plant on a loaded machine lost its first sample that way)."""
    mission = ellipse_mission(tmp_path / "m.toml", 3.0)
    port = free_udp_port()
    with Companion(port, "--arm", "--json", "--mission", str(mission)) as comp, \
            FakeVehicle(port, script=lambda k, ms: {"attitude": k % 16 == 0}) as fake:
        assert comp.wait(30.0) == 0, comp.stderr
        r = comp.result()
    assert r["reason"] == "mission_done" and len(fake.setpoints) > 100
    assert sum(r["telemetry_rejected"].values()) == 0, (r["telemetry_rejected"], comp.stderr)


def test_a_rebooted_vehicle_is_stopped_not_resumed(tmp_path):
    mission = ellipse_mission(tmp_path / "m.toml", 30.0)

    at: list[int] = []

    def reboot(k, ms):
        # 20 ticks into the companion's tracking, not at a fixed tick (see _tracked_from)
        return {"restart": True, "ms": 40} if _tracked_from(fake, at, k) == 20 else None

    port = free_udp_port()
    fake = FakeVehicle(port, script=reboot)     # bound before its thread runs the script
    with Companion(port, "--arm", "--json", "--mission", str(mission)) as comp, fake:
        assert comp.wait(30.0) == 7, comp.stderr
        r = comp.result()
    assert "restarted" in r["reason"]
    assert not any(0 < sp.time_boot_ms < 100_000 for sp in fake.setpoints)
    assert is_zero(fake.setpoints[-1])
    assert any(is_mode_command(c, HOLD) for c in fake.commands)
    assert r["telemetry_rejected"]["time_backwards"] >= 3


def test_a_non_finite_command_is_never_sent(tmp_path):
    """Absurd (but finite) gains make the law's output NaN on the first tracking cycle
    (K_I = k_dc lambda_c overflows to inf, inf * 0 = NaN): the rover is stopped instead."""
    mission = ellipse_mission(tmp_path / "m.toml", 30.0)
    port = free_udp_port()
    with Companion(port, "--arm", "--json", "--mission", str(mission),
                   "--k-dc", "1e200", "--lambda-c", "1e200") as comp, \
            FakeVehicle(port) as fake:
        assert comp.wait(30.0) == 3, comp.stderr
        r = comp.result()
    assert "not finite" in r["reason"] and r["cycles"] == 0
    assert fake.setpoints and all(finite_setpoint(sp) for sp in fake.setpoints)
    assert all(is_zero(sp) for sp in fake.setpoints)
    assert any(is_mode_command(c, HOLD) for c in fake.commands)


def test_a_reboot_that_streams_nothing_is_told_from_a_pilot_by_its_clock(tmp_path):
    """As ArduPilot SITL reboots (tests/sitl/test_ardupilot_field_faults.py): back in MANUAL,
    disarmed, streaming nothing (the companion's message rates died with it), refusing modes
    while it starts. Its mode alone looks like a pilot's; the companion reads its clock
    (MAV_CMD_REQUEST_MESSAGE SYSTEM_TIME) before saying who, and ends with exit 7."""
    mission = ellipse_mission(tmp_path / "m.toml", 30.0)

    at: list[int] = []

    def reboot(k, ms):
        # 20 ticks into the companion's tracking, not at a fixed tick (see _tracked_from)
        return {"reboot": True, "ms": 40} if _tracked_from(fake, at, k) == 20 else None

    port = free_udp_port()
    fake = FakeVehicle(port, script=reboot)     # bound before its thread runs the script
    with Companion(port, "--arm", "--json", "--mission", str(mission)) as comp, fake:
        assert comp.wait(30.0) == 7, comp.stderr
        r = comp.result()
    assert r["reason"].startswith("vehicle_restarted"), r
    assert "pilot took over" not in comp.stderr and "it rebooted" in comp.stderr
    asked = [c for c in fake.commands if c.command == 512 and int(c.param1) == 2]
    assert asked, "the clock was never asked for"
    # not resumed: no GUIDED request nor arming after the clock was asked for
    after = fake.commands[fake.commands.index(asked[0]):]
    assert not any(is_mode_command(c, 15) or c.command == 400 for c in after)


def test_a_pilot_who_takes_a_silent_vehicle_is_not_asked_anything(tmp_path):
    """The mode changes while telemetry flowed (a pilot, as far as anyone can tell) and the
    stream stops with it: the companion listens for the vehicle's clock but asks nothing of a
    vehicle someone else now drives (no MAV_CMD_REQUEST_MESSAGE), and it ends as a pilot's."""
    mission = ellipse_mission(tmp_path / "m.toml", 30.0)
    at: list[int] = []

    def takeover(k, ms):
        # 40 ticks into the companion's tracking, not at a fixed tick: on a loaded machine
        # (4 workers beside the solo tests) tick 80 came before it had engaged, 3 times in 4
        if not at and fake.mode == 15 and fake.armed:
            at.append(k + 40)
        if at and k >= at[0]:
            return {"mode": 0, "silent": True} if k == at[0] else {"silent": True}
        return None

    port = free_udp_port()
    fake = FakeVehicle(port, script=takeover)   # bound before its thread runs the script
    with Companion(port, "--arm", "--json", "--mission", str(mission)) as comp, fake:
        assert comp.wait(30.0) == 4, comp.stderr
        r = comp.result()
    assert r["reason"] == "pilot_override: mode changed to MANUAL by someone else", r
    assert not any(c.command == 512 for c in fake.commands)
