"""PX4's velocity-vector interface in the vehicle model, its identification, the progress floor
of the law and the feasibility check of references (``companion mission check --vehicle``).

The model (``companion.sim.plant``, ``course_gain`` > 0): |u_p| through the speed channel, the
course atan2(u_p) through PX4's proportional course loop into the turn-rate channel, clamped to
|v| / R_min for an Ackermann rover.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from companion.core.filter import FilterGains
from companion.core.limits import Limits
from companion.core.pzc import PZCGains, PZCLaw, PZCTracker
from companion.core.signals import Estimate, Measurement, Reference
from companion.core.trajectory import Ellipse
from companion.errors import UserError
from companion.ident.determinacy import FITTED
from companion.ident.excite import Home, Plan
from companion.ident.excite_vector import VectorExcitation
from companion.ident.fit import fit, rms
from companion.ident.series import Series
from companion.mission.feasibility import check
from companion.profiles import px4
from companion.sim import vehicle_file
from companion.sim.batch import SimConfig, simulate
from companion.sim.plant import RoverModel, RoverParams, RoverState
from testbed.process import companion_cli

ROOT = Path(__file__).resolve().parents[2]

# Close to PX4 SITL's SIH Ackermann rover (RO_* / RA_* defaults of its airframe)
PX4_ROVER = RoverParams(w_c=1 / 0.25, w_c_yaw=1 / 0.05, speed_delay=0.1, yaw_delay=0.04,
                        max_speed=3.0, max_accel=3.0, max_yaw_rate=math.pi, max_yaw_accel=7.0,
                        max_yaw_decel=14.0, course_gain=5.0, min_turn_radius=0.556)


def _drive(params: RoverParams, ux: float, uy: float, seconds: float, v0: float = 0.0,
           h: float = 0.005) -> list[RoverState]:
    model = RoverModel(params)
    s, out = RoverState(v=v0), []
    for _ in range(int(seconds / h)):
        s = model.step_vector(s, ux, uy, h)
        out.append(s)
    return out


# --------------------------------------------------------------------------- the model

def test_a_velocity_vector_is_followed_speed_and_course():
    states = _drive(PX4_ROVER, 0.0, 1.5, 8.0)         # east, from rest facing north
    end = states[-1]
    assert end.v == pytest.approx(1.5, abs=0.01)
    assert end.yaw == pytest.approx(math.pi / 2, abs=0.01)
    assert end.y > 5.0


def test_an_ackermann_rover_cannot_turn_tighter_than_its_radius_nor_on_the_spot():
    at_rest = _drive(PX4_ROVER.with_(speed_delay=0.0, w_c=1e-3), -1.0, 0.0, 2.0)  # speed ~0
    assert max(abs(s.omega) for s in at_rest) < 1e-2           # no speed, no turn
    # a U-turn asked at 1 m/s: it drives its turning circle, never tighter
    states = _drive(PX4_ROVER, -1.0, 0.0, 6.0, v0=1.0)
    assert max(abs(s.omega) / max(abs(s.v), 1e-9) for s in states) <= 1 / 0.556 + 1e-6
    assert min(abs(s.x) for s in states[200:]) >= 0.0
    assert max(s.y for s in states) - min(s.y for s in states) >= 2 * 0.556 - 0.05
    # the same vehicle without the limit turns much tighter
    free = _drive(PX4_ROVER.with_(min_turn_radius=0.0), -1.0, 0.0, 6.0, v0=1.0)
    assert max(s.y for s in free) - min(s.y for s in free) < 2 * 0.556 - 0.2


def test_the_ardupilot_model_is_untouched_by_the_new_fields():
    p = RoverParams.stock_rover()
    assert not p.velocity_vector and p.min_turn_radius == 0.0
    a, b = RoverModel(p), RoverModel(p.with_(course_gain=0.0))
    s1 = s2 = RoverState()
    for _ in range(400):
        s1, s2 = a.step(s1, 1.0, 0.5, 0.005), b.step(s2, 1.0, 0.5, 0.005)
    assert (s1.x, s1.y, s1.yaw) == (s2.x, s2.y, s2.yaw)


def test_batch_sends_a_px4_vehicle_the_velocity_vector_and_arrays_match_floats():
    ref = Ellipse.paper(0.04)
    gains = PZCGains(0.2, 1.0, velocity_ff=True)
    cfg = SimConfig(duration=20.0, control_rate=40.0, max_plant_dt=0.005)
    one = simulate(PZCTracker(FilterGains(1500, 3.5), gains, Limits(6, 6)), PX4_ROVER, ref,
                   None, cfg)
    two = simulate(PZCTracker(FilterGains(1500, 3.5), gains, Limits(6, 6), n=2),
                   PX4_ROVER.with_(course_gain=np.array([5.0, 5.0]),
                                   min_turn_radius=np.array([0.556, 0.556])),
                   Ellipse.paper(np.array([0.04, 0.04])), 2, cfg)
    assert np.allclose(two.steady_rms, one.steady_rms, rtol=1e-6)
    assert one.steady_rms < 0.5


def test_the_progress_floor_keeps_an_ahead_rover_from_turning_round():
    law = PZCLaw(PZCGains(0.5, 2.0, velocity_ff=True, min_progress=0.3))
    ref = Reference(0.0, 0.0, 1.0, 0.0)            # reference going north at 1 m/s
    est = Estimate(3.0, 1.0, 0.0, 1.0, 0.0, 0.0)   # the rover 3 m ahead of it, 1 m east
    cmd = law.step(0.0, est, ref)
    assert cmd.ux == pytest.approx(0.3)            # slows to 30 % of the reference, forward
    assert cmd.uy == pytest.approx(2.5 * -1.0)     # the lateral correction untouched
    assert law.int_x == 0.0 and law.int_y == 0.0
    plain = PZCLaw(PZCGains(0.5, 2.0, velocity_ff=True)).step(0.0, est, ref)
    assert plain.ux < 0                            # without it: turn round


def test_the_progress_floor_prevents_loops_where_the_plain_law_orbits():
    """High position gains on the PX4 rover: the plain law drives loops round the ellipse's
    tight end at 0.08 Hz; with the floor the heading never gets a full turn ahead."""
    def lead(floor: float) -> float:
        tracker = PZCTracker(FilterGains(1500, 3.5), PZCGains(0.12, 7.0, 1.6, 18.0,
                                                               velocity_ff=True,
                                                               min_progress=floor), Limits(6, 6))
        r = simulate(tracker, PX4_ROVER, Ellipse.paper(0.08), None,
                     SimConfig(duration=60.0, control_rate=40.0, max_plant_dt=0.005,
                               trace_every=0.05))
        yaw = np.unwrap(r.trace["yaw"])
        course = np.unwrap(np.arctan2(np.gradient(r.trace["y_ref"]), np.gradient(r.trace["x_ref"])))
        d = yaw - course
        d -= 2 * np.pi * np.round(d[0] / (2 * np.pi))
        return float(np.degrees(np.max(np.abs(d))))
    assert lead(0.3) < 360.0



def test_integrating_past_the_braking_knee_takes_back_an_over_driving_speed_loop():
    """PX4 SIH's speed settles above its command (a throttle feed-forward, no integral action):
    with the position integrators held at the braking curve's knee (0.13 m for these gains, one
    calibration's of 2026-12-04) the rover runs a steady quarter metre ahead, as SIH flew them
    (0.35-0.50 m); integrating on out to four knees (the PX4 profile's) takes the offset back,
    as on SIH (0.085 m). A speed loop that closes is untouched."""
    gains = PZCGains(1.18, 0.855, k_dc_yaw=1.4, lambda_c_yaw=3.0, velocity_ff=True,
                     heading_rate_ff=True, accel_ff=0.38, brake_accel=0.55, brake_yaw_accel=3.47,
                     min_progress=0.3)
    assert px4.PROFILE.tune["brake_integrate"] == 4.0

    def fly(over_drive: float, knees: float) -> tuple[float, float]:
        vehicle = PX4_ROVER.with_(speed_overshoot=over_drive, speed_overshoot_s=math.inf)
        tracker = PZCTracker(FilterGains(948.0, 103.0), replace(gains, brake_integrate=knees),
                             Limits(3.0, math.pi))
        ellipse = Ellipse.paper(0.04)
        r = simulate(tracker, vehicle, ellipse, None,
                     SimConfig(duration=60.0, control_rate=40.0, max_plant_dt=0.02,
                               trace_every=0.05))
        last = r.trace["t"] >= 30.0
        refs = [ellipse.sample(float(t)) for t in r.trace["t"][last]]
        ex, ey = r.trace["x"][last] - r.trace["x_ref"][last], r.trace["y"][last] - r.trace["y_ref"][last]
        ahead = [(x * q.vx + y * q.vy) / math.hypot(q.vx, q.vy) for x, y, q in zip(ex, ey, refs, strict=True)]
        return float(r.steady_rms), float(np.mean(ahead))

    held, ahead_held = fly(0.5, 1.0)
    integrated, ahead_integrated = fly(0.5, 4.0)
    assert held > 0.2 and ahead_held > 0.2                 # 0.25 m, 0.24 m ahead
    assert integrated < 0.5 * held and abs(ahead_integrated) < 0.05
    assert fly(0.0, 4.0) == pytest.approx(fly(0.0, 1.0))   # closed speed loop: inside the knee


def test_the_approach_cone_keeps_a_late_course_loop_from_swinging_across_the_path():
    """PX4 SIH swung one calibration's gains across the path in 2 of 4 flights (2026-12-04):
    a metre's error sent u_p at 60-90 deg to the path, the rover over it at 3-3.6 m/s, and its
    course could not turn back in time. The model does it too on the neighbours of that
    session's vehicle file whose course loop is quicker or later than the fit and whose speed
    over-drives; u_p held within 30 deg of the reference's direction (the PX4 profile's
    approach_cone) swings on none of them, and the vehicle's own figure is unchanged."""
    vehicle = RoverParams(                               # session e2's vehicle file
        w_c=5.974, w_c_yaw=28.84, max_speed=3.0, max_yaw_rate=2.1739, max_accel=3.003,
        max_decel=2.273, max_yaw_accel=5.452, max_yaw_decel=5.238, speed_delay=0.1726,
        yaw_delay=0.0879, speed_turn_coupling=0.0036, course_gain=3.92, min_turn_radius=0.667)
    gains = PZCGains(1.0546, 0.9000, k_dc_yaw=4.710, lambda_c_yaw=1.846, velocity_ff=True,
                     heading_rate_ff=True, accel_ff=0.4325, accel_ff_turn=0.2505,
                     brake_accel=1.5727, min_progress=0.3, brake_integrate=4.0)
    assert px4.PROFILE.tune["approach_cone"] == pytest.approx(math.radians(30.0))
    corners = [(k, late, over) for k in (1.0, 1 / 0.85) for late in (1, 2, 3) for over in (0.2, 0.4)]
    stack = [vehicle.with_(course_gain=vehicle.course_gain * k,
                           yaw_delay=vehicle.yaw_delay + late / 40,
                           speed_delay=vehicle.speed_delay + late / 40,
                           speed_overshoot=over, speed_overshoot_s=math.inf)
             for k, late, over in corners] + [vehicle]
    params = RoverParams(**{f: np.array([float(getattr(v, f)) for v in stack])
                            for f in ("w_c", "w_c_yaw", "max_speed", "max_yaw_rate", "max_accel",
                                      "max_decel", "max_yaw_accel", "max_yaw_decel",
                                      "speed_delay", "yaw_delay", "speed_turn_coupling",
                                      "course_gain", "min_turn_radius", "speed_overshoot",
                                      "speed_overshoot_s")})

    def fly(cone: float) -> np.ndarray:
        tracker = PZCTracker(FilterGains(1179.6, 111.8), replace(gains, approach_cone=cone),
                             Limits(3.0, 2.1739), n=len(stack))
        return np.asarray(simulate(tracker, params, Ellipse.paper(0.04), len(stack),
                                   SimConfig(duration=60.0, control_rate=40.0, max_plant_dt=0.02,
                                             tick=0.02, noise_pos=0.005, noise_yaw=0.002,
                                             seed=1)).steady_rms)

    plain, coned = fly(0.0), fly(math.radians(30.0))
    assert (plain[:-1] > 0.3).sum() >= len(corners) // 2          # most swing, a metre or more
    assert coned[:-1].max() < 0.15                                # none does
    assert coned[-1] == pytest.approx(plain[-1], abs=0.005)       # the vehicle itself: the same


# --------------------------------------------------------------------------- vehicle files

def test_vehicle_file_course_section_round_trips_and_is_optional(tmp_path):
    path = tmp_path / "px4.toml"
    vehicle_file.save(vehicle_file.VehicleFile(PX4_ROVER, name="px4"), path)
    text = path.read_text()
    assert "[course]" in text and "min_turn_radius_m = 0.556" in text
    back = vehicle_file.load(path).params
    assert back.course_gain == 5.0 and back.min_turn_radius == 0.556 and back.velocity_vector
    plain = tmp_path / "ap.toml"
    vehicle_file.save(vehicle_file.VehicleFile(RoverParams.stock_rover()), plain)
    assert "[course]" not in plain.read_text()
    assert not vehicle_file.load(plain).params.velocity_vector
    path.write_text(text.replace("gain_1_s = 5", "gain_1_s = -1"))
    with pytest.raises(UserError, match=r"course.*gain_1_s: must be >= 0, not -1"):
        vehicle_file.load(path)


# --------------------------------------------------------------------------- identification

def _manoeuvre(params: RoverParams, seconds: float = 60.0, rate: float = 40.0) -> Series:
    """The velocity-vector manoeuvre flown on the model: what a PX4 .tlog would hold."""
    model, tracker = RoverModel(params), VectorExcitation(Plan(space=10.0, max_speed=3.0,
                                                                max_yaw_rate=3.0, decel=3.0,
                                                                top_speed=3.0))
    s, h, sub = RoverState(), 0.005, int(round(1 / rate / 0.005))
    rows = []
    for k in range(int(seconds * rate)):
        t = k / rate
        vx, vy = model.velocity(s)
        cmd = tracker.step(t, Measurement(s.x, s.y, s.yaw, vx, vy, s.omega), Home().sample(t))
        rows.append((t, math.hypot(cmd.ux, cmd.uy), math.atan2(cmd.uy, cmd.ux), s.v, s.omega,
                     s.yaw))
        for _ in range(sub):
            s = model.step_vector(s, cmd.ux, cmd.uy, h)
    a = np.array(rows)
    assert tracker.max_distance < 10.5
    return Series(a[:, 0], a[:, 1], np.zeros(len(a)), a[:, 3], a[:, 4], course_cmd=a[:, 2],
                  yaw=np.remainder(a[:, 5] + math.pi, 2 * math.pi) - math.pi)


@pytest.mark.slow   # long: started first under workers (conftest.py)
def test_the_velocity_vector_fit_finds_the_course_gain_and_the_turning_radius():
    truth = PX4_ROVER.with_(course_gain=4.0, min_turn_radius=0.7)
    series = _manoeuvre(truth)
    prior = px4.priors({"RO_SPEED_LIM": 3.0, "RA_WHEEL_BASE": 0.577,
                      "RA_MAX_STR_ANG": 0.5236}).params  # course gain 2, radius 1 m: off
    result = fit(series, prior)
    p = result.params
    assert p.velocity_vector
    assert result.status["course_gain"] == FITTED
    assert result.status["min_turn_radius"] == FITTED
    assert p.min_turn_radius == pytest.approx(0.7, rel=0.15)
    assert p.course_gain == pytest.approx(4.0, rel=0.3)
    # the turn rate as well as the true model predicts it series-parallel (the course loop
    # closed on the heading sampled at 40 Hz, where the vehicle closes it continuously)
    truth_rms = rms(truth, series)
    assert result.speed_rms < 0.05
    assert result.yaw_rate_rms <= 1.1 * truth_rms[1] + 0.01, (result.yaw_rate_rms, truth_rms)


def test_px4_priors_from_its_parameters():
    p = px4.priors({"RO_SPEED_LIM": 3.0, "RO_ACCEL_LIM": 3.0, "RO_DECEL_LIM": 3.0, "RO_YAW_P": 5.0,
                  "RO_YAW_RATE_LIM": 180.0, "RA_WHEEL_BASE": 0.321,
                  "RA_MAX_STR_ANG": 0.5236}).params
    assert p.max_speed == 3.0 and p.course_gain == 5.0
    assert p.max_yaw_rate == pytest.approx(math.pi)
    assert p.min_turn_radius == pytest.approx(0.321 / math.tan(0.5236))


# --------------------------------------------------------------------------- feasibility

def test_a_reference_tighter_than_the_radius_or_braking_harder_is_reported():
    assert check(Ellipse.paper(0.04), 60.0, PX4_ROVER) == []
    tight = Ellipse(f_r=0.2, ax=0.3, bx=0.0, ay=0.0, by=0.3)       # a 0.3 m circle
    kinds = {p.kind for p in check(tight, 10.0, PX4_ROVER)}
    assert "radius" in kinds
    problems = check(Ellipse.paper(0.12), 60.0, PX4_ROVER)
    by_kind = {p.kind: p for p in problems}
    assert by_kind["speed"].worst == pytest.approx(4.77, abs=0.02)
    assert "faster than the vehicle's top speed" in by_kind["speed"].describe()
    slow = PX4_ROVER.with_(max_accel=0.3)
    assert "decel" in {p.kind for p in check(Ellipse.paper(0.08), 60.0, slow)}


def test_mission_check_with_a_vehicle_exits_3_on_a_reference_out_of_reach(tmp_path):
    vehicle = tmp_path / "px4.toml"
    vehicle_file.save(vehicle_file.VehicleFile(PX4_ROVER, name="px4"), vehicle)
    tight = tmp_path / "tight.toml"
    tight.write_text('name = "tight"\nframe = "start"\nduration = 10\n[trajectory]\n'
                     'kind = "circle"\ncenter = [0.0, 0.3]\nradius = 0.3\nspeed = 1.0\n')
    ok = ROOT / "missions" / "paper_ellipse_004.toml"
    p = companion_cli("mission", "check", str(ok),
                      str(tight), "--vehicle", str(vehicle), timeout=60)
    assert p.returncode == 3, p.stderr
    lines = p.stdout.splitlines()
    assert lines[0].startswith(f"{ok}: ok:") and "within" in lines[0]
    assert any("tighter than the minimum turning radius" in line and "radius 0.30 m" in line
               for line in lines[1:]), p.stdout
    p = companion_cli("mission", "check", str(ok),
                      "--vehicle", str(tmp_path / "none.toml"), timeout=60)
    assert p.returncode == 2 and "no such vehicle file" in p.stderr
    assert "Traceback" not in p.stderr
