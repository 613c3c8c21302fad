"""ArduPilot's Ackermann rover (a car): the model's turn-rate clamps (turning radius, lateral
acceleration), the priors its parameters give (ATC_TURN_MAX_G, SERVOn_FUNCTION 26 / 70), the
manoeuvre flown at speed (nothing asked of it at rest), the fit recovering its turning radius,
``mission check --vehicle`` on its lateral acceleration, and the whole live identification
against ``sitl-plant --vehicle`` a car (which then serves a car's frame). Real processes over
loopback UDP, real files; the mathematics pinned by unit tests."""

from __future__ import annotations

import json
import math
from functools import partial

import numpy as np
import pytest

from companion import profiles
from companion.core.limits import Limits
from companion.core.signals import Reference
from companion.ident.determinacy import FITTED
from companion.ident.excite import Excitation, Plan, manoeuvre
from companion.ident.excite_car import CarExcitation
from companion.ident.fit import fit
from companion.ident.series import Series
from companion.mission.feasibility import check
from companion.mission.paths import Circle
from companion.profiles import ackermann, ardupilot, skid
from companion.sim.plant import LAT_ACCEL_MIN_SPEED, RoverModel, RoverParams, RoverState
from companion.sim.vehicle_file import VehicleFile, load, save
from sitl_plant.testing import Pilot, PlantProcess
from testbed.process import companion_cli

G = 9.80665
# Like ArduPilot SITL's `rover` on rover.parm (identified 2026-12-02): 0.9 m turning circle
# radius, ATC_STR_RAT_MAX 120 deg/s, ATC_TURN_MAX_G 0.6, WP_SPEED 5, 1 m/s^2.
CAR = RoverParams(w_c=1.5, w_c_yaw=10.0, max_speed=5.0, max_yaw_rate=math.radians(120.0),
                  max_accel=1.0, max_yaw_accel=math.radians(120.0), speed_delay=0.1,
                  yaw_delay=0.04, min_turn_radius=0.9, max_lat_accel=0.6 * G)
STOCK = {"ATC_ACCEL_MAX": 1.0, "ATC_DECEL_MAX": 0.0, "ATC_STR_ACC_MAX": 120.0,
         "ATC_STR_RAT_MAX": 120.0, "ATC_TURN_MAX_G": 0.6, "WP_SPEED": 5.0, "CRUISE_SPEED": 5.0,
         "CRUISE_THROTTLE": 30.0, "SERVO1_FUNCTION": 26.0, "SERVO3_FUNCTION": 70.0}


companion = partial(companion_cli, timeout=120.0)


# --------------------------------------------------------------------------- the model

def test_a_car_turns_only_while_moving_and_no_faster_than_its_radius_and_lateral_limit():
    model = RoverModel(CAR)
    # at rest: no turn at all, whatever is asked
    assert model.clamp_command(0.0, 2.0, 0.0, 0.0) == (0.0, 0.0)
    # slow: the turning radius, |v| / R
    assert model.clamp_command(0.5, 2.0, 0.0, 0.5)[1] == pytest.approx(0.5 / 0.9)
    # fast: ArduPilot's lateral-acceleration limit, a / |v| (0.6 g at 4 m/s: 1.47 rad/s)
    assert model.clamp_command(4.0, 2.0, 0.0, 4.0)[1] == pytest.approx(0.6 * G / 4.0)
    # reversing turns too (the sign is the setpoint's: ArduPilot flips the steering)
    assert model.clamp_command(-1.0, -2.0, 0.0, -1.0)[1] == pytest.approx(-1.0 / 0.9)
    # below 1 m/s ArduPilot takes the lateral limit at 1 m/s: a skid-steer rover turning in
    # place keeps its whole turn rate
    spinner = RoverModel(RoverParams(max_yaw_rate=2.0, max_lat_accel=1.5))
    assert spinner.clamp_command(0.0, 3.0, 0.0, 0.0)[1] == pytest.approx(1.5 / LAT_ACCEL_MIN_SPEED)
    # many vehicles at once: the same clamps element by element
    batch = RoverModel(CAR.with_(min_turn_radius=np.array([0.9, 0.0, 2.0])), 3)
    _, w = batch.clamp_command(np.full(3, 1.5), np.full(3, 3.0), np.zeros(3), np.full(3, 1.5))
    assert w == pytest.approx([1.5 / 0.9, CAR.max_yaw_rate, 0.75])
    # and a step honours it: a car asked to spin at rest stays put
    s = RoverState()
    for _ in range(1000):
        s = model.step(s, 0.0, 2.0, 0.001)
    assert s.yaw == 0.0 and s.omega == 0.0


# --------------------------------------------------------------------------- priors

def test_ardupilot_parameters_make_a_car_s_priors():
    pri = ardupilot.priors(STOCK)
    assert pri.steering is ackermann.PROFILE
    p = pri.params
    assert p.max_lat_accel == pytest.approx(0.6 * G)
    assert p.min_turn_radius == 1.0 and p.turn_speed_coupling == 0.0
    assert p.speed_turn_coupling == 0.0
    assert pri.describe("max_lat_accel") == "ATC_TURN_MAX_G 0.6"
    assert pri.describe("min_turn_radius") == "Ackermann steering"
    # a skid-steer frame keeps the mixing priors and no turning radius
    skid_pri = ardupilot.priors({**STOCK, "SERVO1_FUNCTION": 73.0, "SERVO3_FUNCTION": 74.0})
    assert skid_pri.steering is skid.PROFILE and skid_pri.params.min_turn_radius == 0.0
    assert skid_pri.params.turn_speed_coupling > 0
    # no servo functions read: no steering kind, the baseline
    assert ardupilot.priors({"ATC_ACCEL_MAX": 1.0}).steering is None
    assert "ATC_TURN_MAX_G" in ardupilot.PRIOR_PARAMS
    assert "SERVO1_FUNCTION" in profiles.prior_params()


def test_the_plant_serves_a_car_s_frame_for_a_car_model():
    served = {n: v for n, v, _ in ardupilot.plant_params(CAR, 50.0, 1, 1.0)}
    assert (served["SERVO1_FUNCTION"], served["SERVO3_FUNCTION"]) == ackermann.PROFILE.servo_functions
    assert served["ATC_TURN_MAX_G"] == pytest.approx(0.6)
    skid_served = {n: v for n, v, _ in ardupilot.plant_params(RoverParams(max_speed=3.0), 50.0,
                                                               1, 1.0)}
    assert (skid_served["SERVO1_FUNCTION"], skid_served["SERVO3_FUNCTION"]) == \
        skid.PROFILE.servo_functions
    assert profiles.steering_of_model(CAR) is ackermann.PROFILE
    assert profiles.steering_of_model(RoverParams()) is skid.PROFILE


# --------------------------------------------------------------------------- the manoeuvre

def fly(plan: Plan, truth: RoverParams, tracker=None, seconds: float = 85.0):
    """The manoeuvre against the model at 40 Hz: (tracker, rows of t, commands, speed, turn
    rate, distance from home)."""
    model = RoverModel(truth)
    state = RoverState(x=3.0, y=-2.0, yaw=1.0)
    tracker = tracker or CarExcitation(plan)
    home = Reference(3.0, -2.0)
    rows, t = [], 0.0
    for _ in range(int(seconds / 0.025)):
        cmd = tracker.step(t, model.measure(state), home)
        rows.append((t, cmd.speed, cmd.yaw_rate, state.v, state.omega,
                     math.hypot(state.x - 3.0, state.y + 2.0)))
        for _ in range(25):
            state = model.step(state, cmd.speed, cmd.yaw_rate, 0.001)
        t += 0.025
    return tracker, np.array(rows)


@pytest.mark.parametrize("space", [6.0, 10.0])
def test_the_car_manoeuvre_turns_only_at_speed_and_stays_within_space(space):
    pri = ardupilot.priors(STOCK)
    tracker = manoeuvre(ardupilot.PROFILE, pri.params, space, Limits(6.0, 6.0), pri.steering)
    assert isinstance(tracker, CarExcitation)
    tracker, rows = fly(tracker.plan, CAR, tracker)
    t, v_cmd, w_cmd, v, w, dist = rows.T
    assert dist.max() <= space
    assert tracker.phase == "done" and abs(v[-1]) < 0.05
    # nothing is asked of it at rest: every turn-rate setpoint comes with a speed setpoint
    assert np.all(np.abs(w_cmd[np.abs(v_cmd) < 0.3]) == 0.0)
    # it reverses, turns to the limit asked at speed and turns tight at a crawl
    assert v_cmd.min() < -0.5
    assert np.any((np.abs(v_cmd) >= 1.5) & (np.abs(w_cmd) == tracker.plan.max_yaw_rate))
    assert np.any((np.abs(v_cmd) <= 0.6) & (np.abs(w_cmd) == tracker.plan.max_yaw_rate)
                  & (np.abs(v_cmd) > 0.1))
    # a skid-steer frame (or none known) keeps the manoeuvre that turns in place
    assert type(manoeuvre(ardupilot.PROFILE, pri.params, space, Limits(6.0, 6.0),
                          skid.PROFILE)) is Excitation


def test_the_fit_recovers_a_car_s_turning_radius_from_its_manoeuvre():
    pri = ardupilot.priors(STOCK)
    plan = manoeuvre(ardupilot.PROFILE, pri.params, 10.0, Limits(6.0, 6.0), pri.steering).plan
    _, rows = fly(plan, CAR)
    t, v_cmd, w_cmd, v, w, _ = rows.T
    result = fit(Series(t, v_cmd, w_cmd, v, w), pri.params)
    assert result.status["min_turn_radius"] == FITTED
    assert result.params.min_turn_radius == pytest.approx(CAR.min_turn_radius, rel=0.05)
    assert result.params.max_accel == pytest.approx(CAR.max_accel, rel=0.1)
    assert result.params.max_lat_accel == pytest.approx(0.6 * G)      # the prior, kept
    assert result.speed_rms < 0.03 and result.yaw_rate_rms < 0.03


# --------------------------------------------------------------------------- mission check

def test_mission_check_names_a_turn_harder_than_the_lateral_limit():
    # 4 m/s on a 4 m circle: 4 m/s^2 of lateral acceleration, turn rate 1 rad/s
    fast = Circle(center=(0.0, 0.0), radius=4.0, speed=4.0)
    problems = check(fast, 20.0, CAR.with_(max_lat_accel=3.0))
    assert [p.kind for p in problems] == ["lat_accel"]
    assert problems[0].worst == pytest.approx(4.0) and problems[0].limit == pytest.approx(3.0)
    assert "lateral-acceleration limit" in problems[0].describe()
    assert check(fast, 20.0, CAR) == []          # 0.6 g = 5.9 m/s^2: within reach
    # slower than 1 m/s ArduPilot allows a turn rate of a, not a / |v|
    slow = Circle(center=(0.0, 0.0), radius=0.25, speed=0.5)       # 2 rad/s, 1 m/s^2
    assert [p.kind for p in check(slow, 10.0, RoverParams(max_lat_accel=1.5))] == ["lat_accel"]


def test_mission_check_vehicle_on_a_car_file(tmp_path):
    car = tmp_path / "car.toml"
    save(VehicleFile(params=CAR.with_(max_lat_accel=1.0), name="car"), car)
    p = companion("mission", "check", "missions/paper_ellipse_008.toml", "--vehicle", str(car))
    assert p.returncode != 0
    assert "lateral-acceleration limit" in p.stdout, p.stdout + p.stderr
    ok = companion("mission", "check", "missions/paper_ellipse_004.toml", "--vehicle", str(car))
    assert ok.returncode == 0, ok.stdout + ok.stderr


def test_a_car_s_vehicle_file_round_trips(tmp_path):
    path = tmp_path / "car.toml"
    save(VehicleFile(params=CAR, name="car"), path)
    back = load(path).params
    assert back.min_turn_radius == pytest.approx(0.9) and back.course_gain == 0.0
    assert back.max_lat_accel == pytest.approx(0.6 * G) and not back.velocity_vector
    text = path.read_text()
    assert "lat_accel_max_m_s2" in text and "min_turn_radius_m = 0.9" in text


def test_a_car_is_never_asked_to_turn_tighter_than_its_radius():
    # The companion's commands to a car (ArduPilot's Ackermann rover) keep |omega| <= |v| / R,
    # at the commanded speed, and hold the yaw integrator while that clamp bites (anti-windup);
    # a skid-steer rover (R 0) and PX4's velocity vectors keep the old clamps.
    from companion.core import ops
    from companion.core.limits import clamp
    from companion.core.pzc import PZCGains, PZCLaw
    from companion.core.signals import Estimate
    from companion.live.policy import GainOptions, KnownVehicle, choose_limits, limits_dict
    from companion.vehicle import vehicle_limits
    lim = vehicle_limits(CAR)
    assert lim.min_turn_radius == pytest.approx(0.9)
    assert vehicle_limits(CAR.with_(course_gain=3.0)).min_turn_radius == 0.0   # PX4's
    assert vehicle_limits(CAR.with_(min_turn_radius=0.0)).min_turn_radius == 0.0
    cmd, speed_free, rate_free = clamp(ops.scalar, lim, 0.9, 2.0, 0.9, 0.0, 0.9)
    assert cmd.yaw_rate == pytest.approx(1.0) and speed_free and not rate_free
    cmd, _, rate_free = clamp(ops.scalar, lim, -0.45, -2.0, -0.45, 0.0, 0.45)   # reversing
    assert cmd.yaw_rate == pytest.approx(-0.5) and not rate_free
    cmd, _, rate_free = clamp(ops.scalar, lim, 0.0, 1.0, 0.0, 0.0, 0.0)        # at rest: none
    assert cmd.yaw_rate == 0.0 and not rate_free
    batch, _, free = clamp(ops.array, lim, np.array([0.9, 3.0]), np.array([2.0, 2.0]),
                           np.zeros(2), np.zeros(2), np.ones(2))
    assert batch.yaw_rate == pytest.approx([1.0, 2.0]) and list(free) == [False, True]
    # the limits a run flies and reports: the vehicle's radius kept under a mission's limits
    flown = choose_limits(None, GainOptions(), KnownVehicle(limits=lim))
    assert flown.min_turn_radius == pytest.approx(0.9)
    assert limits_dict(flown)["min_turn_radius"] == pytest.approx(0.9)
    # the law never commands past it, at any step of a run towards a point behind the car
    law = PZCLaw(PZCGains(k_dc=2.0, lambda_c=1.0), lim)
    for k in range(200):
        cmd = law.step(0.025 * k, Estimate(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), Reference(-3.0, 2.0))
        assert abs(cmd.yaw_rate) <= abs(cmd.speed) / 0.9 + 1e-12


# --------------------------------------------------------------------------- live, sitl-plant

def test_live_identify_of_a_car_on_sitl_plant_flies_at_speed_and_finds_its_radius(tmp_path):
    truth = tmp_path / "car.toml"
    save(VehicleFile(params=CAR, name="a car"), truth)
    out = tmp_path / "identified.toml"
    with PlantProcess("--lockstep", "--vehicle", str(truth)) as plant:
        p = companion("identify", "--connect", f"udpin:127.0.0.1:{plant.port}", "--arm",
                      "--space", "10", "--out", str(out), "--json", "--no-zenoh",
                      "--log-dir", str(tmp_path / "logs"), timeout=300.0)
        with Pilot(plant.port) as pilot:
            # (a lockstep plant holds each step up to its 0.25 s timeout for 1 s of vehicle time
            # after the last setpoint, so its next heartbeat may take about 10 s of wall time
            # when the fit was quick)
            assert pilot.wait("HEARTBEAT", 15.0).custom_mode == 4         # HOLD
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    assert r["flight"]["reason"] == "mission_done" and r["flight"]["max_distance_m"] <= 10.0
    # what the plant served told the companion it is a car
    assert (r["autopilot_params"]["SERVO1_FUNCTION"], r["autopilot_params"]["SERVO3_FUNCTION"]) \
        == (26.0, 70.0)
    assert "steering: Ackermann" in p.stderr
    assert r["params"]["course"]["min_turn_radius_m"] == pytest.approx(0.9, rel=0.05)
    assert r["params"]["turn_rate"]["lat_accel_max_m_s2"] == pytest.approx(0.6 * G, rel=1e-3)
    assert r["status"]["course.min_turn_radius_m"] == "fitted"
    assert load(out).params.min_turn_radius == pytest.approx(0.9, rel=0.05)


# --------------------------------------------------------------------------- ArduPilot SITL

@pytest.mark.sitl
def test_live_identify_on_ardupilot_sitl_rover_finds_a_car(ardupilot, tmp_path):
    """Stock `rover` (ArduPilot's Ackermann frame, rover.parm alone) at 5 x real time: the
    companion reads SERVO1 26 / SERVO3 70, flies the car manoeuvre within 10 m (it turns on
    the spot nowhere), ends in HOLD, and finds SITL's turning circle (SIM_Rover.cpp: 1.8 m
    across at full steering, a 0.9 m radius) within 10 %, a turn-rate clamp no slower than a
    car at 2 m/s turns there, and ArduPilot's lateral limit from ATC_TURN_MAX_G."""
    sitl = ardupilot(speedup=5, model="rover")
    assert all(p.name != "rover-skid.parm" for p in sitl.defaults)
    out = tmp_path / "car.toml"
    p = companion("identify", "--connect", sitl.url(0), "--arm", "--out", str(out), "--json",
                  "--no-zenoh", "--log-dir", str(tmp_path / "logs"), timeout=300.0)
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    assert r["flight"]["reason"] == "mission_done" and r["flight"]["hold_confirmed"]
    assert r["flight"]["max_distance_m"] <= 10.0
    a = r["autopilot_params"]
    assert (a["SERVO1_FUNCTION"], a["SERVO3_FUNCTION"]) == (26.0, 70.0)
    assert "steering: Ackermann" in p.stderr and "car manoeuvre" in p.stderr
    assert r["params"]["course"]["min_turn_radius_m"] == pytest.approx(0.9, rel=0.1)
    assert r["status"]["course.min_turn_radius_m"] == "fitted"
    assert r["params"]["turn_rate"]["lat_accel_max_m_s2"] == pytest.approx(0.6 * G, rel=1e-3)
    assert r["params"]["turn_rate"]["max_rad_s"] >= 1.5
    assert r["rms"]["yaw_rate_rad_s"] < 0.25 and r["rms"]["speed_m_s"] < 0.25
    assert load(out).params.min_turn_radius > 0 and not load(out).params.velocity_vector
