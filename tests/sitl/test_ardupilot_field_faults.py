"""Field faults on the real autopilot (issue 21): ArduPilot Rover SITL (``rover-skid``), the
companion on SERIAL0 (through a stalling TCP proxy where the link is the fault), a ground
station on SERIAL1 that injects the faults as docs/field-faults.md says (SIM_GPS1_GLTCH_X / _Y,
SIM_GPS1_ENABLE by PARAM_SET) and watches the simulator's truth (SIMSTATE), the EKF's report
and the vehicle's pose at 10 Hz.

Faults start 20 s (vehicle) into tracking and last the issue's sizes; the vehicle runs at
``SPEEDUP`` x real time, and stalls are held for their vehicle length / SPEEDUP wall seconds.
Each test prints its figures (the closing note's). Skipped unless ARDUPILOT_SITL or
ARDUPILOT_DIR is set.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from companion.core.pacing import REJOIN_NEAR
from testbed.ardupilot import CompanionProcess, GroundStation
from testbed.field_faults import TO_COMPANION, TO_VEHICLE, StallProxy
from testbed.missions import circle_mission
from testbed.safety import read_tlog
from testbed.scoring import held_reference, largest_error, simstate_xy
from testbed.sitl import ground_speed

SPEEDUP = 2
BOOT_WALL = 120.0 / SPEEDUP + 30.0
ATTITUDE, LOCAL_POSITION_NED, SIMSTATE, EKF_STATUS_REPORT = 30, 32, 164, 193
HOLD, GUIDED = 4, 15
GLITCHING, POS_ABS = 0x8000, 0x10
HEALTHY = 0x33F


def _companion(url: str, tmp_path: Path, mission: Path, *extra: str) -> CompanionProcess:
    return CompanionProcess(url, "--mission", str(mission), "--arm", "--no-zenoh", "--json",
                            "--log-dir", str(tmp_path / "logs"), *extra)


def _watch(gs: GroundStation, timeout: float = 60.0) -> None:
    """10 Hz of what the tests read, on the ground station's link. SITL boots only once the
    companion is on SERIAL0 and may not answer for a while on a loaded machine: asked again
    until it does (set-up, not what is tested)."""
    deadline = time.monotonic() + timeout
    for msg_id in (LOCAL_POSITION_NED, ATTITUDE, SIMSTATE, EKF_STATUS_REPORT):
        while True:
            try:
                assert gs.set_rate(msg_id, 10.0) == 0
                break
            except AssertionError:
                if time.monotonic() > deadline:
                    raise


def _tracking_for(gs: GroundStation, seconds: float) -> int:
    """Until the rover has tracked (armed, GUIDED, moving) for ``seconds`` of vehicle time;
    the vehicle time then (ms)."""
    gs.wait_for("HEARTBEAT", lambda m: m.custom_mode == GUIDED and m.base_mode & 128, BOOT_WALL)
    moving = gs.wait_for("LOCAL_POSITION_NED", lambda m: ground_speed(m) > 0.5, 60.0)
    at = gs.wait_for("LOCAL_POSITION_NED",
                     lambda m: m.time_boot_ms >= moving.time_boot_ms + 1000 * seconds, 60.0)
    return at.time_boot_ms


def _vehicle_seconds(gs: GroundStation, seconds: float, timeout: float = 60.0) -> None:
    """Until ``seconds`` of vehicle time pass (by ATTITUDE: it flows without a position)."""
    t0 = gs.wait_for("ATTITUDE", timeout=10.0).time_boot_ms
    seconds -= 0.1                     # the ground station's ATTITUDE comes at 10 Hz
    gs.wait_for("ATTITUDE", lambda m: m.time_boot_ms >= t0 + 1000 * seconds, timeout)


def _param(gs: GroundStation, name: str, value: float) -> None:
    with gs._lock:
        gs.mav.param_set_send(1, 1, name.encode(), value, 9)     # MAV_PARAM_TYPE_REAL32
    gs.wait_for("PARAM_VALUE", lambda m: m.param_id == name and
                math.isclose(m.param_value, value, rel_tol=1e-3, abs_tol=1e-9), 10.0)


def _seen(gs: GroundStation, kind: str, after: float = 0.0) -> list[tuple[float, object]]:
    with gs._lock:
        return [(w, m) for w, m in gs.seen if w >= after and m.get_type() == kind
                and gs.from_vehicle(m)]


def _estimate_figures(gs, r, flagged, t_end: float) -> dict:
    """From the companion's tlog, on the vehicle's clock (its last ATTITUDE's time_boot_ms):
    the EKF's flag (the first report after tracking began that ``flagged``) and the
    companion's pause (its first zero setpoint or HOLD request after tracking began). From the
    ground station: the truth's largest move from where it was at the flag until the EKF
    reports healthy again."""
    frames, _ = read_tlog(Path(r["tlog"]))
    att_ms, tracking, flag, flag_ms, pause_ms = 0, False, None, None, None
    for _, m in frames:
        kind, ours = m.get_type(), m.get_srcComponent() == 191
        if kind == "ATTITUDE" and not ours:
            att_ms = m.time_boot_ms
        elif kind == "SET_POSITION_TARGET_LOCAL_NED" and ours:
            zero = m.vx == 0.0 and m.yaw_rate == 0.0
            tracking = tracking or not zero
            if tracking and zero and pause_ms is None:
                pause_ms = att_ms
        elif kind == "COMMAND_LONG" and ours and m.command == 176 and int(m.param2) == HOLD:
            if tracking and pause_ms is None:
                pause_ms = att_ms
        elif kind == "EKF_STATUS_REPORT" and not ours and tracking and flag is None \
                and flagged(m.flags):
            flag, flag_ms = m, att_ms
    assert flag is not None and pause_ms is not None, (flag, pause_ms)
    w_flag = next(w for w, m in _seen(gs, "ATTITUDE") if m.time_boot_ms >= flag_ms)
    reports = _seen(gs, "EKF_STATUS_REPORT", t_end)
    w_healthy = next(w for w, m in reports if m.flags & HEALTHY == HEALTHY
                     and not m.flags & GLITCHING)
    healthy_ms = next(m.time_boot_ms for w, m in _seen(gs, "ATTITUDE") if w >= w_healthy)
    truth = [m for w, m in _seen(gs, "SIMSTATE", w_flag) if w <= w_healthy]
    moved = max(math.hypot(*simstate_xy(m, truth[0])) for m in truth)
    return {"flag_ms": flag_ms, "flags": flag.flags, "pause_s": (pause_ms - flag_ms) / 1e3,
            "moved_m": moved, "healthy_after_s": (healthy_ms - flag_ms) / 1e3,
            "frames": frames}


def _why(comp) -> str:
    """The companion's first "estimate unhealthy" log line (what it paused on)."""
    return next((line.split("companion run: ", 1)[-1] for line in comp.stderr.splitlines()
                 if "estimate unhealthy" in line), "(no estimate pause)")


def _companion_modes(frames, after_ms: int, mode: int) -> list:
    """The companion's DO_SET_MODE requests for ``mode`` sent after the sample at ``after_ms``
    (by the setpoints around them in its tlog)."""
    out, last_ms = [], 0
    for _, m in frames:
        if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED" and m.get_srcComponent() == 191:
            last_ms = max(last_ms, m.time_boot_ms)
        elif (m.get_type() == "COMMAND_LONG" and m.get_srcComponent() == 191
              and m.command == 176 and int(m.param2) == mode and last_ms >= after_ms):
            out.append(m)
    return out


@pytest.mark.sitl
@pytest.mark.slow
def test_a_gps_glitch_pauses_within_half_a_second_and_the_rover_stays_put(ardupilot, tmp_path):
    sitl = ardupilot(speedup=SPEEDUP)
    mission = circle_mission(tmp_path / "circle.toml", duration=75.0)
    with _companion(sitl.url(0), tmp_path, mission, "--retake-after-failsafe") as comp, \
            GroundStation(sitl) as gs:
        _watch(gs)
        _tracking_for(gs, 20.0)
        _param(gs, "SIM_GPS1_GLTCH_X", 1e-4)
        _param(gs, "SIM_GPS1_GLTCH_Y", 1e-4)
        _vehicle_seconds(gs, 15.0)
        _param(gs, "SIM_GPS1_GLTCH_X", 0.0)
        _param(gs, "SIM_GPS1_GLTCH_Y", 0.0)
        t_end = time.monotonic()
        code = comp.wait(240.0)
        r = comp.result()
        gs.wait_for("EKF_STATUS_REPORT", lambda m: m.flags & HEALTHY == HEALTHY
                    and not m.flags & GLITCHING, 60.0, t_end)
        f = _estimate_figures(gs, r, lambda flags: flags & GLITCHING, t_end)
    print(f"\nGPS glitch 1e-4 deg x 15 s: EKF flag 0x{f['flags']:x} at {f['flag_ms'] / 1e3:.2f} s; "
          f"companion's zero setpoint {f['pause_s']:+.3f} s after it; true position moved "
          f"{f['moved_m']:.2f} m until the EKF was healthy ({f['healthy_after_s']:.1f} s later); "
          f"exit {code}: {r['reason']}\n  paused on: {_why(comp)}")
    assert "pilot_override" not in r["reason"] and "someone else" not in r["reason"], r
    assert code in (0, 5), comp.stderr
    assert code == 0 or "ekf" in r["reason"], r
    assert "estimate unhealthy" in comp.stderr
    assert f["pause_s"] <= 0.5, f
    assert f["moved_m"] <= 2.0, f


@pytest.mark.sitl
@pytest.mark.slow
def test_gps_lost_pauses_within_a_second_and_the_autopilots_failsafe_is_not_overridden(
        ardupilot, tmp_path):
    sitl = ardupilot(speedup=SPEEDUP)
    mission = circle_mission(tmp_path / "circle.toml", duration=75.0)
    with _companion(sitl.url(0), tmp_path, mission) as comp, GroundStation(sitl) as gs:
        _watch(gs)
        _tracking_for(gs, 20.0)
        _param(gs, "SIM_GPS1_ENABLE", 0.0)
        _vehicle_seconds(gs, 15.0)
        _param(gs, "SIM_GPS1_ENABLE", 1.0)
        t_end = time.monotonic()
        code = comp.wait(240.0)
        r = comp.result()
        gs.wait_for("EKF_STATUS_REPORT", lambda m: m.flags & HEALTHY == HEALTHY, 90.0, t_end)
        _vehicle_seconds(gs, 5.0)
        f = _estimate_figures(gs, r, lambda flags: not flags & POS_ABS, t_end)
        after = [m for w, m in _seen(gs, "HEARTBEAT", t_end)]
    print(f"\nGPS lost x 15 s: EKF flags 0x{f['flags']:x} (no absolute position) at "
          f"{f['flag_ms'] / 1e3:.2f} s; companion's zero setpoint {f['pause_s']:+.3f} s after "
          f"it; true position moved {f['moved_m']:.2f} m until healthy "
          f"({f['healthy_after_s']:.1f} s later); exit {code}: {r['reason']}\n  paused on: "
          f"{_why(comp)}")
    assert "pilot_override" not in r["reason"] and "someone else" not in r["reason"], r
    assert f["pause_s"] <= 1.0, f
    assert f["moved_m"] <= 2.0, f
    if code == 5:
        # the autopilot's failsafe acted: the companion never asked for GUIDED again
        assert not _companion_modes(f["frames"], f["flag_ms"], GUIDED), "re-engaged by itself"
        assert all(m.custom_mode != GUIDED for m in after)
    else:
        assert code == 0 and r["reason"] == "mission_done", comp.stderr


@pytest.mark.sitl
@pytest.mark.slow
@pytest.mark.parametrize("stall_s", [3.0, 10.0])
def test_a_tcp_link_stall_stops_the_rover_and_the_mission_completes(ardupilot, tmp_path,
                                                                   stall_s):
    sitl = ardupilot(speedup=SPEEDUP)
    mission = circle_mission(tmp_path / "circle.toml", duration=50.0)
    with StallProxy(("127.0.0.1", sitl.ports["serial0"])) as proxy, \
            _companion(proxy.url, tmp_path, mission) as comp, GroundStation(sitl) as gs:
        _watch(gs)
        _tracking_for(gs, 15.0)
        t_stall = time.monotonic()
        proxy.stall()
        # held for stall_s of vehicle time, as the ground station's link (not stalled) sees it
        _vehicle_seconds(gs, stall_s)
        proxy.resume()
        t_back = time.monotonic()
        code = comp.wait(180.0)
        r = comp.result()
        poses = [(w, m) for w, m in _seen(gs, "LOCAL_POSITION_NED", t_stall) if w <= t_back]
    speeds = [ground_speed(m) for _, m in poses]
    held_ms = poses[-1][1].time_boot_ms - poses[0][1].time_boot_ms
    # ArduPilot keeps the last target 3 s (its guided timeout), then brakes (~2 s)
    late = [ground_speed(m) for _, m in poses
            if m.time_boot_ms >= poses[0][1].time_boot_ms + 6000]
    print(f"\nTCP stall {stall_s:g} s (held {held_ms / 1e3:.1f} s of vehicle time): speed at "
          f"the start {speeds[0]:.2f} m/s, at the end {speeds[-1]:.2f} m/s"
          + (f", max {max(late):.2f} m/s from 6 s on" if late else "")
          + f"; exit {code}: {r['reason']}, failsafes {r['failsafes']}, "
          f"{r['duration_s']:.1f} s of mission tracked")
    assert code == 0 and r["reason"] == "mission_done", comp.stderr
    assert r["failsafes"] >= 1 and "pilot took over" not in comp.stderr
    assert r["duration_s"] >= 50.0 - 1e-6
    if late:
        assert max(late) < 0.2, late
    # before its guided timeout ArduPilot follows the last setpoint (it may still be speeding
    # up to it): within the mission's speed limit, 2 m/s
    assert max(speeds) <= 2.0 + 0.2, speeds


@pytest.mark.sitl
@pytest.mark.slow
def test_a_tcp_connection_the_autopilot_dropped_is_reopened(ardupilot, tmp_path):
    sitl = ardupilot(speedup=SPEEDUP)
    mission = circle_mission(tmp_path / "circle.toml", duration=40.0)
    with StallProxy(("127.0.0.1", sitl.ports["serial0"])) as proxy, \
            _companion(proxy.url, tmp_path, mission) as comp, GroundStation(sitl) as gs:
        _watch(gs)
        _tracking_for(gs, 10.0)
        proxy.drop()
        code = comp.wait(180.0)
        r = comp.result()
    print(f"\nTCP dropped mid-mission: exit {code}: {r['reason']}, reconnects "
          f"{r['tcp_reconnects']}, failsafes {r['failsafes']}, clients {proxy.clients}")
    assert code == 0 and r["reason"] == "mission_done", comp.stderr
    assert r["tcp_reconnects"] >= 1 and proxy.clients >= 2
    assert "reopened" in comp.stderr


@pytest.mark.sitl
@pytest.mark.slow
@pytest.mark.parametrize("held", [TO_COMPANION, TO_VEHICLE])
def test_a_one_way_tcp_stall_stops_the_rover_and_the_mission_completes(ardupilot, tmp_path,
                                                                      held):
    """10 s (vehicle) of one direction held. TO_COMPANION: the companion hears nothing, its own
    zero setpoint and HOLD reach the vehicle at once; TO_VEHICLE: it hears everything and nothing
    of its own arrives, so ArduPilot's guided timeout stops the rover after 3 s."""
    stall_s = 10.0
    sitl = ardupilot(speedup=SPEEDUP)
    mission = circle_mission(tmp_path / "circle.toml", duration=50.0)
    with StallProxy(("127.0.0.1", sitl.ports["serial0"])) as proxy, \
            _companion(proxy.url, tmp_path, mission) as comp, GroundStation(sitl) as gs:
        _watch(gs)
        _tracking_for(gs, 15.0)
        t_stall = time.monotonic()
        proxy.stall(held)
        _vehicle_seconds(gs, stall_s)
        proxy.resume()
        t_back = time.monotonic()
        code = comp.wait(180.0)
        r = comp.result()
        poses = [(w, m) for w, m in _seen(gs, "LOCAL_POSITION_NED", t_stall) if w <= t_back]
        after = [m for w, m in _seen(gs, "LOCAL_POSITION_NED", t_back)]
        modes = [m.custom_mode for w, m in _seen(gs, "HEARTBEAT", t_stall) if w <= t_back]
    t0 = poses[0][1].time_boot_ms
    speeds = [ground_speed(m) for _, m in poses]
    # the rover is stopped from here on (ms into the stall): TO_COMPANION by the companion's
    # own zero setpoint and HOLD (its 0.5 s stale timeout, 1 s of vehicle time, then braking);
    # TO_VEHICLE by ArduPilot's 3 s guided timeout, then braking
    stop_from = 4000 if held == TO_COMPANION else 6000
    late = [ground_speed(m) for _, m in poses if m.time_boot_ms >= t0 + stop_from]
    stopped_at = next((m.time_boot_ms - t0 for _, m in poses
                       if all(ground_speed(n) < 0.2 for _, n in poses
                              if n.time_boot_ms >= m.time_boot_ms)), None)
    after_max = max((ground_speed(m) for m in after), default=0.0)
    err = largest_error(r["csv"], 5.0)
    paused_s, ref_moved_s, err_back = held_reference(r["csv"])
    print(f"\nTCP stall {stall_s:g} s, {held} held: speed at the start {speeds[0]:.2f} m/s, "
          f"below 0.2 m/s from {stopped_at / 1e3 if stopped_at is not None else float('nan'):.1f}"
          f" s into the stall, max {max(late):.2f} m/s from {stop_from / 1e3:g} s on; HOLD "
          f"{'seen' if HOLD in modes else 'not seen'} during the stall; max speed after it "
          f"{after_max:.2f} m/s; tracking paused {paused_s:.1f} s (vehicle), the reference moved "
          f"{ref_moved_s:.3f} s meanwhile, error {err_back:.2f} m on taking up; largest tracking error from 5 s of mission on "
          f"{err:.2f} m; exit {code}: {r['reason']}, failsafes {r['failsafes']}, "
          f"{r['duration_s']:.1f} s of mission tracked")
    assert code == 0 and r["reason"] == "mission_done", comp.stderr
    assert "pilot took over" not in comp.stderr
    assert r["duration_s"] >= 50.0 - 1e-6
    assert max(late) < 0.2, late
    assert max(speeds) <= 2.0 + 0.2, speeds
    # the reference was held while the rover stood (TO_VEHICLE: from ArduPilot's guided
    # timeout, 3 s in, when the companion hears of it) and taken up where the rover came to
    # rest: it moved on by what the rover drove before stopping, no further; without the hold
    # it ran on 10 s and the rover chased it at 1.7 m/s, 5.6 m behind
    assert paused_s >= stall_s - 4.0, paused_s
    assert ref_moved_s <= stop_from / 1e3 and err_back <= REJOIN_NEAR, (ref_moved_s, err_back)
    if held == TO_COMPANION:
        assert "telemetry stale" in comp.stderr
        assert HOLD in modes, modes        # the companion's own HOLD, obeyed during the stall
    else:
        assert "our setpoints stopped arriving" in comp.stderr


@pytest.mark.sitl
@pytest.mark.slow
def test_an_autopilot_reboot_mid_mission_ends_the_run_not_resumed(ardupilot, tmp_path):
    """A ground station reboots the armed autopilot (MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN with
    ArduPilot's force value 20190226 in y: refused while armed without it). SITL re-executes
    itself without -w (parameters kept), drops its TCP connections and boots again once the
    companion has reopened SERIAL0. The companion must end the run with exit 7, not resume."""
    sitl = ardupilot(speedup=SPEEDUP)
    mission = circle_mission(tmp_path / "circle.toml", duration=60.0)
    with _companion(sitl.url(0), tmp_path, mission, "--lost-timeout", "60") as comp, \
            GroundStation(sitl) as gs:
        _watch(gs)
        ms_reboot = _tracking_for(gs, 15.0)
        t_reboot = time.monotonic()
        with gs._lock:
            gs.mav.command_int_send(1, 1, 0, 246, 0, 0, 1.0, 0.0, 0.0, 0.0, 0, 20190226, 0.0)
        code = comp.wait(180.0)
        took = time.monotonic() - t_reboot
        r = comp.result()
        acks = [m.result for m in gs.messages("COMMAND_ACK", t_reboot) if m.command == 246]
    frames, _ = read_tlog(Path(r["tlog"]))
    # the companion's tlog from the vehicle's first message after the reboot that carries its
    # clock (its clock behind the reboot's); what the companion asked for from there on
    clocked = [(i, m.time_boot_ms) for i, (_, m) in enumerate(frames)
               if m.get_type() in ("ATTITUDE", "LOCAL_POSITION_NED", "SYSTEM_TIME")
               and m.get_srcComponent() == 1]
    rebooted = next(j for j, (_, ms) in enumerate(clocked) if ms >= ms_reboot - 1000)
    back = next((i for i, ms in clocked[rebooted:] if ms < ms_reboot - 5000), None)
    asked = [m for _, m in frames[back or len(frames):]
             if m.get_type() == "COMMAND_LONG" and m.get_srcComponent() == 191
             and (m.command == 400 or (m.command == 176 and int(m.param2) == GUIDED))]
    clock = (f"its clock read {frames[back][1].time_boot_ms / 1e3:.1f} s "
             f"({frames[back][1].get_type()})" if back is not None else "its clock never read")
    print(f"\nAutopilot rebooted {ms_reboot / 1e3:.1f} s after boot (ACK {acks}): exit {code} "
          f"{took:.1f} s later ({clock}): {r['reason']}; reconnects {r.get('tcp_reconnects')}, "
          f"failsafes {r['failsafes']}; GUIDED / arm requests after the reboot: {len(asked)}")
    assert acks[:1] == [0], acks
    assert code == 7 and r["reason"].startswith("vehicle_restarted"), comp.stderr
    assert "pilot took over" not in comp.stderr and "it rebooted" in comp.stderr
    assert back is not None and not asked, asked


@pytest.mark.sitl
@pytest.mark.slow
def test_the_battery_failsafe_is_named_as_such(ardupilot, tmp_path):
    """A low battery (issue 44): BATT_FS_LOW_ACT 2 (Hold) and BATT_LOW_VOLT above what the
    simulated battery gives, 20 s into tracking (SITL's battery is SIM_BATT_VOLTAGE 12.6 V, its
    monitor BATT_MONITOR 4). The autopilot says "Battery 1 is low ..." and switches to HOLD
    after BATT_LOW_TIMER s; the companion must end naming the battery failsafe, not a pilot."""
    sitl = ardupilot(speedup=SPEEDUP, params={"BATT_FS_LOW_ACT": 2, "BATT_LOW_TIMER": 2})
    mission = circle_mission(tmp_path / "circle.toml", duration=75.0)
    with _companion(sitl.url(0), tmp_path, mission) as comp, GroundStation(sitl) as gs:
        _watch(gs)
        _tracking_for(gs, 20.0)
        t_low = time.monotonic()
        _param(gs, "BATT_LOW_VOLT", 13.0)
        code = comp.wait(120.0)
        r = comp.result()
        texts = [m.text for m in gs.messages("STATUSTEXT", t_low)]
        modes = [m.custom_mode for m in gs.messages("HEARTBEAT", t_low)]
    print(f"\nbattery low: the autopilot said {texts}; modes {sorted(set(modes))}; exit {code}: "
          f"{r['reason']}")
    assert any("battery" in t.lower() for t in texts), texts
    assert HOLD in modes, modes
    assert code == 5 and "battery" in r["reason"].lower(), (r["reason"], comp.stderr[-2000:])
    assert "pilot_override" not in r["reason"] and "someone else" not in r["reason"], r
