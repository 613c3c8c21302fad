"""Each preflight check on its own: a vehicle set up right passes, each way of setting it up
wrong fails or warns with the parameter and what to set (companion.preflight.checks, pure)."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from companion.live.params import decode, encode
from companion.preflight.checks import (
    FAIL,
    OK,
    WARN,
    Ekf,
    Limits,
    Observed,
    Streams,
    exit_code,
    fixes,
    run_checks,
)

GOOD_PARAMS = {
    "FRAME_CLASS": 1, "FRAME_TYPE": 0, "SERVO1_FUNCTION": 73, "SERVO3_FUNCTION": 74,
    "SERVO2_FUNCTION": 0, "FS_GCS_ENABLE": 1, "FS_ACTION": 2, "FS_GCS_TIMEOUT": 5,
    "MAV_GCS_SYSID": 255, "MAV_OPTIONS": 0, "SCHED_LOOP_RATE": 50,
    "ATC_ACCEL_MAX": 1.0, "ATC_DECEL_MAX": 0.0, "ATC_STR_RAT_MAX": 120.0,
    "ATC_STR_ACC_MAX": 120.0, "CRUISE_SPEED": 3.0, "CRUISE_THROTTLE": 75, "WP_SPEED": 3.0}
GOOD = Observed(
    autopilot="ardupilot", mav_type=10, modes=frozenset({"MANUAL", "HOLD", "GUIDED"}),
    mavlink_version=2, signing_key=True, signed=True, params=GOOD_PARAMS,
    sensors=(0x10000000 | 0x20, 0x10000000 | 0x20, 0x10000000 | 0x20),
    ekf=Ekf(0x33F, 0.01, 0.02, 0.01, 0.02), origin=(-35.36, 149.16),
    streams=Streams(40.0, {"LOCAL_POSITION_NED": 0, "ATTITUDE": 0},
                    {"LOCAL_POSITION_NED": 40.2, "ATTITUDE": 40.2}))


def rows(obs: Observed) -> dict[str, object]:
    out = {r.name: r for r in run_checks(obs)}
    assert len(out) == len(run_checks(obs)), "two checks share a name"
    return out


def with_params(**changes) -> Observed:
    return replace(GOOD, params={**GOOD_PARAMS, **changes})


def test_a_vehicle_set_up_right_passes_every_check_and_exits_0():
    r = run_checks(GOOD)
    assert [x.name for x in r if x.status != OK] == []
    assert exit_code(r) == 0
    assert fixes(r, GOOD.params) == {}
    for x in r:
        assert set(x.as_dict()) == {"name", "status", "value", "want", "why"}
        assert x.value and x.want and x.why


@pytest.mark.parametrize("obs, name, status, value_part", [
    (replace(GOOD, mav_type=2), "HEARTBEAT type", FAIL, "not a rover"),
    (replace(GOOD, mav_type=11), "HEARTBEAT type", OK, "boat"),
    (with_params(SERVO1_FUNCTION=26, SERVO3_FUNCTION=70), "FRAME_CLASS, SERVOn_FUNCTION", WARN,
     "Ackermann"),
    (with_params(SERVO1_FUNCTION=0, SERVO3_FUNCTION=0), "FRAME_CLASS, SERVOn_FUNCTION", FAIL,
     "no throttle outputs"),
    (with_params(FRAME_CLASS=3), "FRAME_CLASS, SERVOn_FUNCTION", FAIL, "FRAME_CLASS 3"),
    (with_params(FRAME_TYPE=1), "FRAME_CLASS, SERVOn_FUNCTION", WARN, "omni"),
    (replace(GOOD, mavlink_version=1), "MAVLink", WARN, "MAVLink 1"),
    (replace(GOOD, origin=None), "GPS_GLOBAL_ORIGIN", FAIL, "not set"),
    (replace(GOOD, ekf=None), "EKF_STATUS_REPORT", WARN, "no answer"),
    (replace(GOOD, ekf=Ekf(0x1)), "EKF_STATUS_REPORT", FAIL, "relative position"),
    (replace(GOOD, ekf=Ekf(0x33F | 32768)), "EKF_STATUS_REPORT", FAIL, "GPS glitching"),
    (replace(GOOD, ekf=Ekf(0x33F, 0.6)), "EKF_STATUS_REPORT", WARN, "velocity variance 0.60"),
    (replace(GOOD, ekf=Ekf(0x33F, 0.1, 0.9)), "EKF_STATUS_REPORT", FAIL, "position variance"),
    (replace(GOOD, ekf=Ekf(0x33F & ~16)), "EKF_STATUS_REPORT", WARN, "no absolute position"),
    (replace(GOOD, sensors=(0x10000000, 0x10000000, 0), prearm_texts=("PreArm: GPS",)),
     "SYS_STATUS pre-arm", FAIL, "PreArm: GPS"),
    (replace(GOOD, sensors=(0x20, 0x20, 0)), "SYS_STATUS pre-arm", FAIL, "GPS"),
    (replace(GOOD, sensors=None), "SYS_STATUS pre-arm", WARN, "no SYS_STATUS"),
    (replace(GOOD, sensors=(0x10000000, 0x10000000, 0), armed=True), "SYS_STATUS pre-arm", OK,
     "armed"),
    (replace(GOOD, modes=frozenset({"MANUAL"})), "GUIDED", FAIL, "not among"),
    (with_params(FS_GCS_ENABLE=0), "FS_GCS_ENABLE", WARN, "0 (off)"),
    (with_params(FS_ACTION=0), "FS_ACTION", WARN, "nothing"),
    (with_params(FS_GCS_TIMEOUT=30), "FS_GCS_TIMEOUT", WARN, "30 s"),
    (with_params(FS_GCS_TIMEOUT=1), "FS_GCS_TIMEOUT", WARN, "1 s"),
    (with_params(MAV_GCS_SYSID=250), "MAV_GCS_SYSID", WARN, "250"),
    (with_params(MAV_GCS_SYSID=250, MAV_OPTIONS=1), "MAV_GCS_SYSID", FAIL, "enforcing"),
    (with_params(MAV_GCS_SYSID=250, MAV_GCS_SYSID_HI=255, MAV_OPTIONS=1), "MAV_GCS_SYSID", OK,
     "250..255"),
    (with_params(ATC_ACCEL_MAX=0), "ATC_ACCEL_MAX", WARN, "no limit"),
    (with_params(ATC_STR_RAT_MAX=0), "ATC_STR_RAT_MAX", WARN, "no limit"),
    (with_params(ATC_STR_ACC_MAX=0), "ATC_STR_ACC_MAX", WARN, "no limit"),
    (with_params(ATC_DECEL_MAX=-1), "ATC_DECEL_MAX", WARN, "-1"),
    (with_params(CRUISE_THROTTLE=0), "WP_SPEED, CRUISE_SPEED / CRUISE_THROTTLE", WARN,
     "CRUISE_THROTTLE 0"),
    (replace(GOOD, signing_key=False, signed=False), "signing", WARN, "unsigned"),
    (replace(GOOD, signing_key=False, signed=False, serial=True), "signing", OK, "serial"),
    (replace(GOOD, signing_key=False, signed=True), "signing", WARN, "no key"),
    (replace(GOOD, streams=None), "LOCAL_POSITION_NED, ATTITUDE rate", WARN, "not measured"),
    (replace(GOOD, streams=Streams(40.0, {"LOCAL_POSITION_NED": 0, "ATTITUDE": 0},
                                   {"LOCAL_POSITION_NED": None, "ATTITUDE": 40.0})),
     "LOCAL_POSITION_NED, ATTITUDE rate", FAIL, "LOCAL_POSITION_NED none"),
    (replace(GOOD, streams=Streams(40.0, {"LOCAL_POSITION_NED": 0, "ATTITUDE": 0},
                                   {"LOCAL_POSITION_NED": 20.0, "ATTITUDE": 20.0})),
     "LOCAL_POSITION_NED, ATTITUDE rate", WARN, "20.0 Hz"),
])
def test_each_way_of_getting_it_wrong_is_named(obs, name, status, value_part):
    r = rows(obs)[name]
    assert r.status == status, r
    assert value_part in r.value, r
    # and the other checks are not disturbed
    assert all(x.status == OK for n, x in rows(obs).items() if n != name) or \
        name == "HEARTBEAT type"


def test_the_onboard_identity_leaves_the_gcs_failsafe_to_the_ground_station():
    """The companion as the vehicle's own system (component 191): MAV_GCS_SYSID 255 is right
    (and MAV_OPTIONS enforcing drops nothing of ours: measured on SITL, docs/ground-station.md);
    one naming the vehicle's own id would let the companion hide a lost ground station."""
    onboard = replace(GOOD, companion_sysid=1, vehicle_sysid=1)
    r = rows(onboard)
    assert all(x.status == OK for x in r.values()), [x for x in r.values() if x.status != OK]
    assert "not taken for the ground station" in r["MAV_GCS_SYSID"].why
    assert rows(replace(onboard, params={**GOOD_PARAMS, "MAV_OPTIONS": 1}))[
        "MAV_GCS_SYSID"].status == OK
    wrong = rows(replace(onboard, params={**GOOD_PARAMS, "MAV_GCS_SYSID": 1}))["MAV_GCS_SYSID"]
    assert wrong.status == WARN and wrong.fix == {"MAV_GCS_SYSID": 255.0}
    off = rows(replace(onboard, params={**GOOD_PARAMS, "FS_GCS_ENABLE": 0}))["FS_GCS_ENABLE"]
    assert off.status == WARN and "ground station" in off.why


def test_a_missing_parameter_is_a_warning_that_says_so():
    params = dict(GOOD_PARAMS)
    del params["FS_GCS_ENABLE"]
    r = rows(replace(GOOD, params=params))["FS_GCS_ENABLE"]
    assert (r.status, r.value) == (WARN, "not reported")


def test_older_firmware_names_sysid_mygcs_and_sysid_enforce():
    params = {k: v for k, v in GOOD_PARAMS.items() if not k.startswith("MAV_")}
    r = rows(replace(GOOD, params={**params, "SYSID_MYGCS": 250, "SYSID_ENFORCE": 1}))
    assert r["SYSID_MYGCS"].status == FAIL and "SYSID_ENFORCE" in r["SYSID_MYGCS"].value
    assert r["SYSID_MYGCS"].fix == {"SYSID_MYGCS": 255.0}


def test_a_refused_rate_recommends_the_loop_rate_that_allows_it():
    obs = replace(GOOD, params={**GOOD_PARAMS, "SCHED_LOOP_RATE": 20},
                  streams=Streams(40.0, {"LOCAL_POSITION_NED": 2, "ATTITUDE": 2},
                                  {"LOCAL_POSITION_NED": 1.0, "ATTITUDE": 1.0}))
    r = rows(obs)["LOCAL_POSITION_NED, ATTITUDE rate"]
    assert r.status == WARN and r.fix == {"SCHED_LOOP_RATE": 50.0}
    assert "reboot" in r.why


def test_the_vehicle_file_is_held_against_the_autopilots_limits():
    matching = Limits(max_speed=3.2, max_accel=1.05, max_decel=1.05,
                      max_yaw_rate=math.radians(120), max_yaw_accel=2.07)
    assert all(x.status == OK for x in run_checks(replace(GOOD, limits=matching)))
    off = replace(matching, max_accel=3.0, max_speed=6.0)
    r = rows(replace(GOOD, limits=off))
    assert r["ATC_ACCEL_MAX"].status == WARN and "3 m/s^2" in r["ATC_ACCEL_MAX"].want
    assert r["WP_SPEED, CRUISE_SPEED / CRUISE_THROTTLE"].status == WARN
    assert r["ATC_STR_RAT_MAX"].status == OK


def test_fixes_are_the_failsafe_values_for_parameters_the_vehicle_has():
    obs = with_params(FS_GCS_ENABLE=0, FS_ACTION=0, FS_GCS_TIMEOUT=30, MAV_GCS_SYSID=250,
                      ATC_ACCEL_MAX=0)
    r = run_checks(obs)
    assert exit_code(r) == 1
    assert fixes(r, obs.params) == {"FS_GCS_ENABLE": 1.0, "FS_ACTION": 2.0,
                                    "FS_GCS_TIMEOUT": 5.0, "MAV_GCS_SYSID": 255.0}


PX4_GOOD = replace(GOOD, autopilot="px4", modes=frozenset({"MANUAL", "OFFBOARD", "LOITER"}),
                   params={"CA_AIRFRAME": 6, "COM_OF_LOSS_T": 0.5, "COM_OBL_RC_ACT": 5})


@pytest.mark.parametrize("changes, name, status", [
    ({}, "COM_OF_LOSS_T", OK), ({}, "COM_OBL_RC_ACT", OK), ({}, "CA_AIRFRAME", OK),
    ({}, "OFFBOARD", OK),
    ({"COM_OF_LOSS_T": 5.0}, "COM_OF_LOSS_T", WARN),
    ({"COM_OBL_RC_ACT": 0}, "COM_OBL_RC_ACT", WARN),
    ({"CA_AIRFRAME": 5}, "CA_AIRFRAME", WARN),
    ({"CA_AIRFRAME": 0}, "CA_AIRFRAME", FAIL),
])
def test_px4_offboard_failsafes_and_airframe(changes, name, status):
    obs = replace(PX4_GOOD, params={**PX4_GOOD.params, **changes})
    assert rows(obs)[name].status == status
    if status == WARN and name.startswith("COM_"):
        assert fixes(run_checks(obs), obs.params) == {
            "COM_OF_LOSS_T": {"COM_OF_LOSS_T": 1.0}, "COM_OBL_RC_ACT": {"COM_OBL_RC_ACT": 5.0}
        }[name]


def test_px4_limits_are_not_claimed_checked():
    r = rows(PX4_GOOD)["inner-loop limits"]
    assert r.status == WARN and r.value == "not read"


@pytest.mark.parametrize("value, ptype", [(5, 6), (-3, 6), (200, 1), (-7, 2), (65000, 3),
                                          (1.25, 9)])
def test_px4_bytewise_values_round_trip_and_ardupilot_values_are_plain(value, ptype):
    raw = encode(value, ptype, bytewise=True)
    assert decode(raw, ptype, bytewise=True) == value
    assert encode(value, ptype, bytewise=False) == value
    if ptype != 9:
        assert raw != value     # the bytes, not the number
