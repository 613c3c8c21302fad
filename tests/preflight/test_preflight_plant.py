"""``companion preflight`` end to end against a real ``sitl-plant`` process over loopback UDP:
every check passing on a plant set up right, and each one failing or warning on a plant set up
wrong (its --param / --ekf-delay / --loop-rate / --mavlink1 / --mav-type / --signing-key flags);
``--fix --yes`` sets the parameters, reads them back, and they stay set for the next run."""

from __future__ import annotations

import json
import math
import os
import pty
import subprocess
import sys
from pathlib import Path

import pytest

from companion.sim.vehicle_file import load as load_vehicle
from companion.sim.vehicle_file import preset_path
from sitl_plant.testing import Pilot, PlantProcess, free_udp_port

ROOT = Path(__file__).resolve().parents[2]
SKID = str(ROOT / "companion" / "sim" / "vehicles" / "ardupilot_skid.toml")
STEERING = "FRAME_CLASS, SERVOn_FUNCTION"
STREAMS = "LOCAL_POSITION_NED, ATTITUDE rate"
TOP_SPEED = "WP_SPEED, CRUISE_SPEED / CRUISE_THROTTLE"

PRESET = load_vehicle(preset_path("ardupilot-skid")).params   # what the plant serves


def preflight(port: int, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "companion", "preflight", "--connect",
                           f"udpin:127.0.0.1:{port}", "--heartbeat-timeout", "5", *args],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT,
                          stdin=subprocess.DEVNULL)


def checks(result: subprocess.CompletedProcess) -> dict[str, dict]:
    rows = json.loads(result.stdout)["checks"]
    for row in rows:
        assert set(row) == {"name", "status", "value", "want", "why"}
    return {row["name"]: row for row in rows}


def statuses(result) -> dict[str, str]:
    return {name: row["status"] for name, row in checks(result).items()}


@pytest.fixture
def key(tmp_path):
    path = tmp_path / "key"
    path.write_bytes(os.urandom(32))
    path.chmod(0o600)
    return str(path)


def test_a_plant_set_up_right_passes_every_check_and_exits_0(key):
    with PlantProcess("--preset", "ardupilot-skid", "--signing-key", key,
                      "--param", "FS_GCS_ENABLE=1") as plant:
        r = preflight(plant.port, "--json", "--vehicle", SKID, "--signing-key", key)
    assert r.returncode == 0, r.stdout + r.stderr
    s = statuses(r)
    assert set(s.values()) == {"ok"}, s
    c = checks(r)
    assert c["HEARTBEAT type"]["value"].startswith("rover")
    assert c[STEERING]["value"].startswith("skid-steer")
    rates = [float(w) for w in c[STREAMS]["value"].replace("(", " ").split() if w[0].isdigit()]
    assert len(rates) == 3 and all(abs(hz - 40.0) < 1.0 for hz in rates), rates  # 2 + asked
    assert c["GPS_GLOBAL_ORIGIN"]["value"].startswith("-35.36326")
    assert c["ATC_STR_RAT_MAX"]["value"] == f"{math.degrees(PRESET.max_yaw_rate):.6g} deg/s"
    assert c["signing"]["value"].startswith("signed")

    # the text form, one line per check; unsigned on a network link is a warning (exit 1)
    with PlantProcess("--preset", "ardupilot-skid", "--param", "FS_GCS_ENABLE=1") as plant:
        text = preflight(plant.port, "-q")
    lines = text.stdout.strip().splitlines()
    assert text.returncode == 1 and text.stderr == ""
    assert len(lines) == len(s)
    assert [line.split()[0] for line in lines] == ["ok"] * (len(s) - 1) + ["warn"]
    assert lines[-1].startswith("warn  signing") and "want MAVLink 2 signing" in lines[-1]


def test_a_plant_set_up_wrong_fails_each_check_and_names_it():
    with PlantProcess("--preset", "paper", "--ekf-delay", "600", "--loop-rate", "20",
                      "--mavlink1", "--param", "FS_GCS_ENABLE=0", "--param", "FS_ACTION=0",
                      "--param", "FS_GCS_TIMEOUT=30", "--param", "MAV_OPTIONS=1",
                      "--param", "MAV_GCS_SYSID=250", "--param", "FRAME_CLASS=3",
                      "--param", "ATC_DECEL_MAX=-1") as plant:
        # as a ground station's id (the companion's before 2026-12-02): MAV_OPTIONS enforcing
        # another GCS id drops it (the onboard identity's rows: test_preflight_checks.py)
        r = preflight(plant.port, "--json", "--source-system", "255")
    assert r.returncode == 1, r.stderr
    s, c = statuses(r), checks(r)
    assert s == {
        "HEARTBEAT type": "ok", STEERING: "fail", "MAVLink": "warn", STREAMS: "warn",
        "GPS_GLOBAL_ORIGIN": "fail", "EKF_STATUS_REPORT": "fail", "SYS_STATUS pre-arm": "fail",
        "GUIDED": "ok", "FS_GCS_ENABLE": "warn", "FS_ACTION": "warn", "FS_GCS_TIMEOUT": "warn",
        "MAV_GCS_SYSID": "fail", "ATC_ACCEL_MAX": "warn", "ATC_DECEL_MAX": "warn",
        "ATC_STR_RAT_MAX": "warn", "ATC_STR_ACC_MAX": "warn", TOP_SPEED: "warn",
        "signing": "warn"}
    assert c["MAVLink"]["value"] == "MAVLink 1"
    assert "refused" in c[STREAMS]["value"] and "SCHED_LOOP_RATE 50" in c[STREAMS]["want"]
    assert "PreArm" in c["SYS_STATUS pre-arm"]["value"]
    assert "not set" == c["GPS_GLOBAL_ORIGIN"]["value"]
    assert "drop" in c["MAV_GCS_SYSID"]["why"]


def test_a_vehicle_that_is_not_a_rover_and_steers_like_a_car():
    with PlantProcess("--mav-type", "0", "--param", "SERVO1_FUNCTION=26",
                      "--param", "SERVO3_FUNCTION=70") as plant:
        r = preflight(plant.port, "--json")
    s = statuses(r)
    assert (s["HEARTBEAT type"], s[STEERING], s["GUIDED"]) == ("fail", "warn", "fail")
    assert "Ackermann" in checks(r)[STEERING]["value"]


def test_a_boat_is_a_boat_and_the_vehicle_file_is_held_against_the_limits():
    with PlantProcess("--preset", "ardupilot-skid", "--max-accel", "3", "--max-speed", "6",
                      "--param", "FRAME_CLASS=2", "--dropout", "1") as plant:
        r = preflight(plant.port, "--json", "--vehicle", SKID)
    s, c = statuses(r), checks(r)
    assert s["HEARTBEAT type"] == "ok" and c["HEARTBEAT type"]["value"].startswith("boat")
    assert s["ATC_ACCEL_MAX"] == "warn" and f"{PRESET.max_accel:.3g} m/s^2" in c["ATC_ACCEL_MAX"]["want"]
    assert s[TOP_SPEED] == "warn"
    assert s["ATC_STR_RAT_MAX"] == "ok"
    assert s[STREAMS] == "fail" and "none" in c[STREAMS]["value"]   # every pose message lost


def test_fix_yes_sets_reads_back_and_the_values_stay_for_the_next_run():
    with PlantProcess("--preset", "ardupilot-skid", "--param", "FS_ACTION=0",
                      "--param", "FS_GCS_TIMEOUT=30", "--param", "MAV_OPTIONS=1",
                      "--param", "MAV_GCS_SYSID=250", "--param-loss", "0.3") as plant:
        gcs_id = ("--source-system", "255")     # the rows for a companion heart-beating as 255
        before = preflight(plant.port, "--json", "--fix", *gcs_id)    # no --yes, no terminal
        fixed = preflight(plant.port, "--json", "--fix", "--yes", *gcs_id)
        after = preflight(plant.port, "--json", *gcs_id)
    assert before.returncode == 2 and "--yes" in before.stderr and before.stdout == ""
    assert fixed.returncode == 1, fixed.stderr              # unsigned still warns
    out = json.loads(fixed.stdout)
    assert {f["name"]: (f["from"], f["to"], f["read_back"], f["ok"]) for f in out["fixes"]} == {
        "FS_GCS_ENABLE": (0, 1, 1, True), "FS_ACTION": (0, 2, 2, True),
        "FS_GCS_TIMEOUT": (30, 5, 5, True), "MAV_GCS_SYSID": (250, 255, 255, True)}
    assert "asked for again" in fixed.stderr                # --param-loss: indices re-read
    for r in (fixed, after):
        s = statuses(r)
        assert [n for n, v in s.items() if v != "ok"] == ["signing"], s


def _on_a_terminal(port: int, answer: bytes) -> subprocess.CompletedProcess:
    """--fix without --yes, stdin a terminal (a pseudo-terminal) that answers ``answer``."""
    master, slave = pty.openpty()
    try:
        os.write(master, answer)
        return subprocess.run([sys.executable, "-m", "companion", "preflight", "--connect",
                               f"udpin:127.0.0.1:{port}", "--json", "--fix"], stdin=slave,
                              capture_output=True, text=True, timeout=60, cwd=ROOT)
    finally:
        os.close(master)
        os.close(slave)


def test_fix_asks_on_a_terminal_and_sets_nothing_unless_told_yes():
    with PlantProcess("--param", "FS_ACTION=0") as plant:
        no = _on_a_terminal(plant.port, b"n\n")
        yes = _on_a_terminal(plant.port, b"y\n")
    assert "FS_ACTION: 0 -> 2" in no.stderr and "[y/N]" in no.stderr
    assert no.returncode == 1 and "fixes" not in json.loads(no.stdout)
    assert statuses(no)["FS_ACTION"] == "warn"
    assert {f["name"] for f in json.loads(yes.stdout)["fixes"]} == {"FS_ACTION", "FS_GCS_ENABLE"}
    assert statuses(yes)["FS_ACTION"] == "ok"


def test_px4_offboard_failsafes_are_fixed_through_bytewise_integers():
    with PlantProcess("--autopilot", "px4", "--param", "COM_OF_LOSS_T=5",
                      "--param", "COM_OBL_RC_ACT=0", "--param", "CA_AIRFRAME=5") as plant:
        before = preflight(plant.port, "--json")
        r = preflight(plant.port, "--json", "--fix", "--yes")
        again = preflight(plant.port, "--json")
    s = statuses(before)
    assert (s["COM_OF_LOSS_T"], s["COM_OBL_RC_ACT"], s["CA_AIRFRAME"]) == ("warn",) * 3
    assert checks(before)["CA_AIRFRAME"]["value"].startswith("Ackermann")
    out = json.loads(r.stdout)
    assert {f["name"]: (f["from"], f["read_back"]) for f in out["fixes"]} == {
        "COM_OF_LOSS_T": (5, 1), "COM_OBL_RC_ACT": (0, 5)}
    s = statuses(again)
    assert (s["COM_OF_LOSS_T"], s["COM_OBL_RC_ACT"], s["OFFBOARD"], s["CA_AIRFRAME"]) == \
        ("ok", "ok", "ok", "warn")                          # the frame is not --fix's to change
    assert checks(again)["COM_OBL_RC_ACT"]["value"] == "5 (Hold)"


def _interval_us(pilot: Pilot, msg_id: int) -> int:
    pilot.mav.command_long_send(1, 1, 510, 0, msg_id, 0, 0, 0, 0, 0, 0)
    return pilot.wait("MESSAGE_INTERVAL", cond=lambda m: m.message_id == msg_id).interval_us


def test_the_pose_streams_get_their_rates_back_after_the_measurement():
    """A companion already streaming on the link keeps its rates: preflight puts them back."""
    with PlantProcess() as plant:
        with Pilot(plant.port) as pilot:
            pilot.wait("HEARTBEAT")
            assert pilot.set_rate(32, 10) == 0 and pilot.set_rate(30, -1) == 0
        r = preflight(plant.port, "--json")
        assert "40.0 Hz" in checks(r)[STREAMS]["value"]
        with Pilot(plant.port) as pilot:
            pilot.wait("HEARTBEAT")
            assert (_interval_us(pilot, 32), _interval_us(pilot, 30)) == (100_000, -1)


def test_a_signed_vehicle_and_no_key_could_not_check_exit_2(key):
    with PlantProcess("--signing-key", key) as plant:     # it refuses unsigned requests
        r = preflight(plant.port, "--json")
    assert r.returncode == 2 and r.stdout == ""
    assert "signs its messages" in r.stderr and "--signing-key" in r.stderr


def test_a_key_the_vehicle_does_not_sign_with_could_not_check_exit_2(key, tmp_path):
    other = tmp_path / "other"
    other.write_bytes(os.urandom(32))
    other.chmod(0o600)
    with PlantProcess("--signing-key", key) as plant:
        r = preflight(plant.port, "--signing-key", str(other), "--heartbeat-timeout", "2")
    assert r.returncode == 2 and "check --signing-key" in r.stderr


def test_no_vehicle_and_bad_flags_could_not_check_exit_2(tmp_path):
    r = preflight(free_udp_port(), "--heartbeat-timeout", "0.5")
    assert r.returncode == 2 and "no heartbeat" in r.stderr and "Traceback" not in r.stderr
    r = preflight(free_udp_port(), "--vehicle", str(tmp_path / "nope.toml"))
    assert r.returncode == 2 and "nope.toml" in r.stderr and "Traceback" not in r.stderr
    r = preflight(free_udp_port(), "--yes")
    assert r.returncode == 2 and "--fix" in r.stderr
