"""``companion run`` against a scripted vehicle whose own health fails (issue 21): the estimate
flagged or stepped pauses the run and it resumes once healthy; the autopilot's own failsafe is
never taken back; a pilot during the companion's failsafe is a pilot. Real processes, real UDP.

The vehicle is :class:`testbed.fake_vehicle.FakeVehicle` (ArduPilot-like: heartbeats, ACKs,
EKF_STATUS_REPORT, STATUSTEXT on its script). Each test checks what went on the wire.
"""

from __future__ import annotations

from sitl_plant.testing import free_udp_port
from testbed.fake_vehicle import FakeVehicle, is_mode_command, is_zero
from testbed.missions import ellipse_mission
from testbed.process import Companion

HEALTHY, GLITCHING, NO_GPS = 0x33F, 0x833F, 0x27     # ArduPilot SITL's flags (field-faults.md)
GUIDED, HOLD, MANUAL = 15, 4, 0
CRITICAL, ACTIVE = 5, 4


CELL: dict = {}      # the running FakeVehicle, for scripts that note what was sent so far


def run(tmp_path, script, *flags, duration=8.0):
    mission = ellipse_mission(tmp_path / "m.toml", duration, f_r=0.05)
    port = free_udp_port()
    CELL.clear()
    with Companion(port, "--arm", "--json", "--no-zenoh", "--no-log", "--mission", str(mission),
                   "--estimate-healthy-for", "0.5", *flags) as comp, \
            FakeVehicle(port, script=script) as fake:
        CELL["fake"] = fake
        code = comp.wait(60.0)
        return code, comp.result(), comp, fake


def note_commands(key):
    """In a script: remember how many commands the companion had sent by this tick."""
    fake = CELL.get("fake")
    CELL[key] = len(fake.commands) if fake is not None else 0


def test_a_gps_glitch_pauses_at_once_and_the_run_resumes_once_healthy(tmp_path):
    def script(k, ms):
        if k % 8 == 0:                                        # 5 Hz reports
            return {"ekf": GLITCHING if 120 <= k < 200 else HEALTHY}
        return None

    code, r, comp, fake = run(tmp_path, script)
    assert code == 0 and r["reason"] == "mission_done", comp.stderr
    assert "estimate unhealthy: EKF_STATUS_REPORT flags 0x833f: GPS glitching" in comp.stderr
    assert "estimate healthy again" in comp.stderr and r["failsafes"] == 1
    # from the report on: zero setpoints only, until 0.5 s after the last bad one
    t_bad = fake.sent_ms[120][0]
    t_good = fake.sent_ms[200][0]
    during = [sp for sp in fake.setpoints if t_bad < sp.time_boot_ms < t_good + 400]
    assert during and all(is_zero(sp) for sp in during)
    assert any(is_mode_command(c, HOLD) for c in fake.commands)
    assert any(not is_zero(sp) for sp in fake.setpoints if sp.time_boot_ms > t_good + 600)


def test_a_position_step_never_reaches_the_controller(tmp_path):
    def script(k, ms):
        out = {"ekf": HEALTHY} if k % 8 == 0 else {}
        if k >= 150:
            out["x"] = 14.0                                  # the fall-back to DCM: 14 m at once
        return out

    code, r, comp, fake = run(tmp_path, script, "--on-bad-estimate", "end")
    assert code == 6, comp.stderr
    assert r["reason"].startswith("estimate_unhealthy: LOCAL_POSITION_NED stepped 14.00 m")
    t_step = fake.sent_ms[150][0]
    answered = [sp for sp in fake.setpoints if sp.time_boot_ms >= t_step]
    assert answered and all(is_zero(sp) for sp in answered)


def test_the_autopilots_ekf_failsafe_is_never_taken_back(tmp_path):
    """It switches to HOLD itself, says so and turns critical: exit 5, nothing more sent."""
    def script(k, ms):
        if k == 150:
            note_commands("at_failsafe")
            return {"text": "EKF failsafe", "status": CRITICAL, "mode": HOLD}
        if k == 400:
            return {"text": "EKF failsafe cleared", "status": ACTIVE}
        return None

    code, r, comp, fake = run(tmp_path, script, duration=15.0)
    assert code == 5 and r["stop_cause"] == "autopilot_failsafe", comp.stderr
    assert r["reason"].startswith("autopilot_failsafe: the autopilot's ekf failsafe"), r
    assert "pilot_override" not in r["reason"] and "someone else" not in r["reason"]
    t_fs = fake.sent_ms[150][0]
    after = fake.commands[CELL["at_failsafe"]:]
    assert not [c for c in after if c.command in (176, 400)], after    # no mode, no arming
    assert not [sp for sp in fake.setpoints if sp.time_boot_ms > t_fs + 100]


def gps_lost(k, ms):
    """The flags lose absolute position; 2 s later the autopilot's EKF failsafe begins (the
    companion's HOLD is in place by then); it clears 3 s later, with the flags."""
    out = {"ekf": NO_GPS if 120 <= k < 300 else HEALTHY} if k % 8 == 0 else {}
    if k == 200:
        out.update(text="EKF failsafe", status=CRITICAL)
    if k == 330:
        out.update(text="EKF failsafe cleared", status=ACTIVE)
    return out


def test_gps_lost_pauses_and_the_autopilots_failsafe_then_ends_it(tmp_path):
    code, r, comp, fake = run(tmp_path, gps_lost, duration=10.0)
    assert code == 5, comp.stderr
    assert "no absolute horizontal position" in comp.stderr
    assert r["reason"].startswith("autopilot_failsafe: the autopilot's ekf failsafe"), r
    assert "estimate failsafe" in r["reason"]
    assert len([c for c in fake.commands if is_mode_command(c, GUIDED)]) == 1   # never again
    assert all(is_zero(sp) for sp in fake.setpoints if sp.time_boot_ms > fake.sent_ms[120][0])


def test_gps_lost_with_retake_resumes_once_the_autopilots_failsafe_has_cleared(tmp_path):
    code, r, comp, fake = run(tmp_path, gps_lost, "--retake-after-failsafe", duration=10.0)
    assert code == 0 and r["reason"] == "mission_done", comp.stderr
    t_clear = fake.sent_ms[330][0]
    resumed = [sp for sp in fake.setpoints if sp.time_boot_ms > fake.sent_ms[120][0]
               and not is_zero(sp)]
    assert resumed and resumed[0].time_boot_ms > t_clear, "resumed before the failsafe cleared"
    assert len([c for c in fake.commands if is_mode_command(c, GUIDED)]) >= 2


def test_without_the_flag_gps_lost_can_end_the_run_with_its_reason(tmp_path):
    def script(k, ms):
        return {"ekf": NO_GPS if k >= 120 else HEALTHY} if k % 8 == 0 else None

    code, r, comp, fake = run(tmp_path, script, "--on-bad-estimate", "end")
    assert code == 6 and "no absolute horizontal position" in r["reason"], comp.stderr


def test_a_pilot_during_the_companions_own_failsafe_is_a_pilot(tmp_path):
    """Telemetry goes silent (the companion asks HOLD); a pilot picks MANUAL meanwhile: when
    telemetry returns the companion does not take the vehicle back."""
    def script(k, ms):
        if k == 185:
            note_commands("at_pilot")
        if 150 <= k < 190:
            return {"silent": True, **({"mode": MANUAL} if k == 185 else {})}
        return None

    code, r, comp, fake = run(tmp_path, script)
    assert code == 4, comp.stderr
    assert r["reason"] == "pilot_override: mode changed to MANUAL by someone else", r
    after = fake.commands[CELL["at_pilot"]:]
    assert not [c for c in after if is_mode_command(c, GUIDED)], "GUIDED after the pilot's MANUAL"


def test_a_mode_the_autopilot_chose_during_a_stall_is_not_taken_back(tmp_path):
    """Telemetry and heartbeats go silent; when they return the vehicle is in RTL, critical
    (an offboard-loss RTL, a GCS failsafe): the companion, re-engaging, does not ask GUIDED."""
    def script(k, ms):
        if k == 150:
            note_commands("at_stall")
        if 150 <= k < 200:
            return {"silent": True}
        if k == 200:
            return {"mode": 11, "status": CRITICAL}          # RTL
        return None

    code, r, comp, fake = run(tmp_path, script)
    assert code == 5 and r["stop_cause"] == "autopilot_failsafe", comp.stderr
    assert "switched to RTL" in r["reason"], r
    guided = [c for c in fake.commands[CELL["at_stall"]:] if is_mode_command(c, GUIDED)]
    assert len(guided) <= 1, guided    # at most one asked before the RTL heartbeat came


BOOTING = 0xA7     # ArduPilot SITL just after boot: no position yet, constant-position mode


def test_a_vehicle_without_a_position_yet_is_waited_for_not_failed(tmp_path):
    """Powered on moments ago: the EKF has no position for the first 3 s (120 ticks). The
    companion asks nothing of the vehicle (no arming, no motion) until it is healthy, then
    flies the mission; no failsafe is counted."""
    def booting(k, ms):
        if k == 119:
            note_commands("before_healthy")
        return {"ekf": BOOTING if k < 120 else HEALTHY} if k % 8 == 0 else None

    code, r, comp, fake = run(tmp_path, booting)
    assert code == 0 and r["reason"] == "mission_done", comp.stderr
    assert r["failsafes"] == 0
    assert "waiting for a healthy position estimate before engaging" in comp.stderr
    before = fake.commands[:CELL["before_healthy"]]
    assert not [c for c in before if c.command == 400], "armed before the estimate was healthy"
    assert [c for c in fake.commands if c.command == 400 and c.param1 == 1]
    moving = [sp for sp in fake.setpoints if not is_zero(sp)]
    assert moving and moving[0].time_boot_ms > fake.sent_ms[120][0]


def test_a_position_that_never_comes_ends_the_run_with_exit_6_and_says_what_to_do(tmp_path):
    def never(k, ms):
        return {"ekf": BOOTING} if k % 8 == 0 else None

    code, r, comp, fake = run(tmp_path, never, "--estimate-wait", "2")
    assert code == 6 and r["stop_cause"] == "estimate_unhealthy", comp.stderr
    assert "no healthy position estimate within 2 s of start" in r["reason"], r
    assert "--estimate-wait" in r["reason"]
    assert not [c for c in fake.commands if c.command == 400 and c.param1 == 1]   # never armed
    assert all(is_zero(sp) for sp in fake.setpoints)
    # never asked anything, so not stopped with a HOLD either: the vehicle is left as it was
    assert not [c for c in fake.commands if c.command == 176], comp.stderr
    assert "left as it was" in comp.stderr


def test_our_setpoints_lost_one_way_pause_until_the_vehicle_hears_us_again(tmp_path):
    """The link is silent towards the vehicle only (telemetry flows): ArduPilot stops the rover
    in GUIDED and says "target not received last 3secs, stopping". The companion pauses at
    once (zero setpoint, HOLD asked, the reference held) and resumes only once the vehicle has
    its HOLD (the link carries its messages again); the mission completes."""
    def script(k, ms):
        if 120 <= k < 200:
            tick = {"deaf": True}
            if k == 160:
                tick["text"] = "target not received last 3secs, stopping"
            return tick
        return None

    code, r, comp, fake = run(tmp_path, script)
    assert code == 0 and r["reason"] == "mission_done", comp.stderr
    assert "our setpoints stopped arriving" in comp.stderr and r["failsafes"] == 1
    assert "pilot took over" not in comp.stderr
    t_text = fake.sent_ms[160][0]
    lost_after = [m for m in fake.lost if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
                  and m.time_boot_ms > t_text]
    # from the text on, zero setpoints only while nothing arrives (the reference held) ...
    assert lost_after and all(is_zero(sp) for sp in lost_after)
    assert any(is_mode_command(c, HOLD) for c in fake.lost if c.get_type() == "COMMAND_LONG")
    # ... and once it hears again: the HOLD, then GUIDED, then tracking from where it was held
    heard = [c for c in fake.commands if c.command == 176]
    first_hold = next(i for i, c in enumerate(heard) if is_mode_command(c, HOLD))
    assert any(is_mode_command(c, GUIDED) for c in heard[first_hold:])
    t_back = fake.sent_ms[200][0]
    assert any(not is_zero(sp) for sp in fake.setpoints if sp.time_boot_ms > t_back)
    assert r["duration_s"] >= 8.0 - 1e-6
