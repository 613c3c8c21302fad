"""``companion identify``: the fit recovers a known vehicle (synthetic data from ``respond``, a
``companion run`` log and a live manoeuvre against ``sitl-plant --vehicle FILE``), parameters a
log does not excite take their priors, the manoeuvre stays within ``--space`` and ends in HOLD,
and a bad log is one line with exit code 2. Real processes over loopback UDP, real files."""

from __future__ import annotations

import csv
import functools
import json
import math
import os
import signal
import struct
import subprocess
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from companion.core.signals import Reference
from companion.ident import channels
from companion.ident.determinacy import BOUND, FITTED, PRIOR
from companion.ident.excite import Excitation, Plan
from companion.ident.fit import fit, rms
from companion.ident.series import Series, join
from companion.live.flightlog import CSV_FIELDS
from companion.logs.logread import read_csv
from companion.profiles import ardupilot
from companion.profiles.priors import defaults
from companion.sim.plant import RoverModel, RoverParams, RoverState
from companion.sim.response import respond
from companion.sim.vehicle_file import VehicleFile, load, save
from sitl_plant.testing import Pilot, PlantProcess, free_udp_port
from testbed.marks import CANDIDATE
from testbed.missions import ellipse_mission
from testbed.process import ROOT, Companion, companion_cli
from testbed.safety import read_tlog

# Fits are CPU-bound and some tests run three of them: under make test's load beside a SITL suite
# the longest took 222 s of the 300 s default (pyproject.toml). The guard is against a hang.
pytestmark = pytest.mark.timeout(900)

# A vehicle like ArduPilot's rover-skid: every part of the model switched on (the mixer takes
# speed while turning and turn rate at speed).
TRUE = RoverParams(w_c=4.0, w_c_yaw=15.0, max_speed=3.5, max_yaw_rate=2.0, max_accel=1.0,
                   max_decel=1.4, max_yaw_accel=2.2, max_yaw_decel=3.0, speed_delay=0.08,
                   yaw_delay=0.04, turn_speed_coupling=0.3, speed_turn_coupling=0.15)


# (a guard against a hung run, not a speed target: a two-log fit took over 120 s of wall
# under make test's load beside a SITL suite; speed is the benchmarks' business)
companion = partial(companion_cli, timeout=400.0)


def one_line_error(p: subprocess.CompletedProcess, needle: str) -> None:
    assert p.returncode == 2, p.stderr
    assert "Traceback" not in p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("companion identify: error:"), p.stderr
    assert needle in lines[0], lines[0]


def steps(rng: np.random.Generator, t: np.ndarray, low: float, high: float, hold: float):
    k = (t // hold).astype(int)
    return rng.uniform(low, high, k.max() + 1)[k]


def synthetic(params: RoverParams, seconds: float, speed_amp: float, rate_amp: float,
              seed: int = 1, noise: float = 0.02, stop: float = 0.0) -> Series:
    """ArduPilot-like 20/20/20/40 ms samples, random setpoint steps (zero for the last ``stop``
    seconds), the model's response on a 1 ms grid plus measurement noise."""
    rng = np.random.default_rng(seed)
    t = np.concatenate([[0.0], np.cumsum(np.tile([0.02, 0.02, 0.02, 0.04], int(seconds / 0.1)))])
    u = np.clip(steps(rng, t, -0.5 * speed_amp, speed_amp, 2.5), -2.0, None)
    w = steps(rng, t, -rate_amp, rate_amp, 1.7)
    u[t > t[-1] - stop] = 0.0
    w[t > t[-1] - stop] = 0.0
    v, om = respond(params, t, u, w, 1, 0.001)
    return Series(t, u, w, v[:, 0] + noise * rng.standard_normal(len(t)),
                  om[:, 0] + noise * rng.standard_normal(len(t)))


def within(value: float, truth: float, rel: float) -> bool:
    return abs(value - truth) <= rel * abs(truth)


# --------------------------------------------------------------------------- the fit, pure

def test_the_search_runs_respond_s_model_one_channel_at_a_time():
    """The fit's channel-at-a-time stepping is respond's model, step for step."""
    rng = np.random.default_rng(7)
    series = synthetic(TRUE, 20.0, speed_amp=4.5, rate_amp=2.6)
    n = 6
    params = RoverParams(
        w_c=rng.uniform(1, 20, n), w_c_yaw=rng.uniform(1, 30, n), max_speed=rng.uniform(2, 5, n),
        max_yaw_rate=rng.uniform(1, 3, n), max_accel=rng.uniform(0.5, 3, n),
        max_decel=rng.uniform(0.5, 3, n), max_yaw_accel=rng.uniform(1, 5, n),
        max_yaw_decel=rng.uniform(1, 5, n), speed_delay=rng.uniform(0, 0.2, n),
        yaw_delay=rng.uniform(0, 0.2, n), turn_speed_coupling=rng.uniform(0, 0.8, n),
        speed_turn_coupling=rng.uniform(0, 0.5, n), speed_overshoot=rng.uniform(0, 0.6, n),
        speed_overshoot_s=rng.uniform(0.3, 2, n), yaw_overshoot=rng.uniform(-0.8, 1.5, n),
        yaw_overshoot_s=rng.uniform(0.2, 2, n))
    s = series
    for dt in (0.01, 0.02):
        v, w = respond(params, s.t, s.speed_cmd, s.yaw_rate_cmd, n, dt, v0=0.3, omega0=-0.2)
        # respond's speed on every grid step (respond sampled at the grid's own times, one
        # extra point so float rounding cannot drop the last step): what the turn-rate
        # channel's coupling reads.
        g = channels.Grid.of(s.t, dt)
        tg = s.t[0] + dt * np.arange(g.steps + 1)
        held = np.append(g.held, g.held[-1])
        v_grid, _ = respond(params, tg, s.speed_cmd[held], s.yaw_rate_cmd[held], n, dt,
                            v0=0.3, omega0=-0.2)
        w2, grid = channels.turn_rate(s.t, s.yaw_rate_cmd, n, dt, -0.2, params.yaw_delay,
                                      params.yaw_bandwidth, params.max_yaw_rate,
                                      params.max_yaw_accel, params.yaw_decel,
                                      params.speed_turn_coupling, v_grid[:g.steps],
                                      params.max_speed, overshoot=params.yaw_overshoot,
                                      overshoot_s=params.yaw_overshoot_s)
        v2 = channels.speed(s.t, s.speed_cmd, grid, n, dt, 0.3, params.speed_delay, params.w_c,
                            params.max_speed, params.max_accel, params.decel,
                            params.turn_speed_coupling, params.max_yaw_rate,
                            params.speed_overshoot, params.speed_overshoot_s)
        np.testing.assert_allclose(w2, w, rtol=0, atol=1e-12)
        np.testing.assert_allclose(v2, v, rtol=0, atol=1e-12)


def test_fit_recovers_known_parameters_from_noisy_data():
    series = synthetic(TRUE, 60.0, speed_amp=4.5, rate_amp=2.6)
    result = fit(series, defaults())
    p = result.params
    # (TRUE's loops do not overshoot: how long an overshoot would last is not seen)
    status = {k: v for k, v in result.status.items()
              if k not in ("speed_overshoot_s", "yaw_overshoot_s")}
    assert all(s == FITTED for s in status.values()), result.status
    assert p.speed_overshoot < 0.03 and result.status["speed_overshoot_s"] == PRIOR
    assert abs(p.yaw_overshoot) < 0.03 and result.status["yaw_overshoot_s"] == PRIOR
    for name in ("max_accel", "max_decel", "max_yaw_accel", "max_yaw_decel", "max_yaw_rate"):
        assert within(getattr(p, name), getattr(TRUE, name), 0.05), (name, getattr(p, name))
    assert within(p.max_speed, TRUE.max_speed, 0.1)
    assert abs(p.speed_delay - TRUE.speed_delay) <= 0.025
    assert abs(p.yaw_delay - TRUE.yaw_delay) <= 0.025
    assert within(p.w_c, TRUE.w_c, 0.3) and within(p.yaw_bandwidth, TRUE.yaw_bandwidth, 0.3)
    assert abs(p.turn_speed_coupling - TRUE.turn_speed_coupling) <= 0.12
    assert abs(p.speed_turn_coupling - TRUE.speed_turn_coupling) <= 0.05
    # The RMS is the noise's (0.02), not the model's error.
    assert result.speed_rms < 0.026 and result.yaw_rate_rms < 0.026
    assert rms(TRUE, series)[0] <= result.speed_rms * 1.05


@pytest.mark.parametrize("share", [-0.45, 0.6])
def test_fit_finds_the_turn_rate_loops_two_time_scales(share):
    """A rate loop whose feed-forward under-drives (share < 0: a late tail the integrator pulls
    up, ATC_STR_RAT_FF too low) or over-drives it (> 0: an overshoot it takes back): the fit
    finds the share and the slow time constant, and the model explains the log to the noise."""
    truth = TRUE.with_(yaw_overshoot=share, yaw_overshoot_s=0.8)
    series = synthetic(truth, 60.0, speed_amp=4.5, rate_amp=2.6)
    result = fit(series, defaults())
    p = result.params
    assert result.status["yaw_overshoot"] == FITTED
    assert result.status["yaw_overshoot_s"] == FITTED
    assert abs(p.yaw_overshoot - share) < 0.08, p.yaw_overshoot
    assert within(p.yaw_overshoot_s, 0.8, 0.25), p.yaw_overshoot_s
    assert result.yaw_rate_rms < 0.026
    # the same model with one time scale does not explain the log: what the term is for
    assert rms(p.with_(yaw_overshoot=0.0), series)[1] > 2.0 * result.yaw_rate_rms


def test_fit_finds_an_overshoot_the_motors_cap_at_speed():
    """A feed-forward that over-drives (share 0.6) on a skid-steer rover whose mixer leaves
    half the turn rate at full speed: turning in place the rate overshoots whole, driving fast
    it stops at the clamp (SITL rover-skid with ATC_STR_RAT_FF 0.5, 2026-12-05). The model's
    cap (actuator.turn_rate_cap) is what the fit searches, so it finds the share, the slow time
    constant and the coupling, and explains the log to the noise."""
    truth = TRUE.with_(yaw_overshoot=0.6, yaw_overshoot_s=0.8, speed_turn_coupling=0.5)
    series = synthetic(truth, 60.0, speed_amp=4.5, rate_amp=2.6)
    # the log has both: overshoots past the target at rest and rates held at the cap at speed
    top = truth.max_yaw_rate * (1 - 0.5 * np.minimum(np.abs(series.speed) / truth.max_speed, 1))
    fast = np.abs(series.speed) > 2.0
    assert np.sum(fast & (np.abs(series.yaw_rate) > top - 0.06)) > 100
    assert np.all(np.abs(series.yaw_rate[fast]) < top[fast] + 0.1)     # 5 sigma of the noise
    result = fit(series, defaults())
    p = result.params
    assert abs(p.yaw_overshoot - 0.6) < 0.1, p.yaw_overshoot
    # the cap where the log drives (the coupling and the top speed trade off above it)
    for v in (0.0, 1.0, 2.0, 3.0):
        cap = RoverModel(p).tops(0.0, v)[1]
        assert abs(cap - RoverModel(truth).tops(0.0, v)[1]) < 0.1, (v, cap)
    assert result.yaw_rate_rms < 0.026


def test_logs_fitted_together_determine_what_each_leaves_to_its_prior():
    # One flight turns on the spot (the speed channel is never driven), the other drives
    # straight (the turn-rate channel never): each alone leaves a channel at its prior; joined,
    # one model explains both and the limits of both channels are found. Each flight ends at
    # rest, as a log cut by identify does (join's premise).
    turning = synthetic(TRUE, 33.0, speed_amp=0.0, rate_amp=2.6, seed=3, stop=3.0)
    driving = synthetic(TRUE, 33.0, speed_amp=4.5, rate_amp=0.0, seed=4, stop=3.0)
    for part, blind in ((turning, "max_accel"), (driving, "max_yaw_accel")):
        assert fit(part, defaults()).status[blind] == PRIOR
    both = join([turning, driving])
    assert len(both.t) == len(turning.t) + len(driving.t) and np.all(np.diff(both.t) > 0)
    result = fit(both, defaults())
    assert within(result.params.max_accel, TRUE.max_accel, 0.05), result.params
    assert within(result.params.max_yaw_accel, TRUE.max_yaw_accel, 0.05), result.params
    for part in (turning, driving):
        assert max(rms(result.params, part)) < 0.03      # the noise's 0.02, on each flight


def test_parameters_the_log_does_not_excite_take_their_priors():
    # Small setpoints: no clamp is reached, no turn fast enough for the coupling to bite.
    series = synthetic(TRUE, 40.0, speed_amp=1.2, rate_amp=0.9, seed=2)
    priors = ardupilot.priors({"ATC_STR_RAT_MAX": 100.0, "CRUISE_SPEED": 3.0,
                             "CRUISE_THROTTLE": 60.0})
    result = fit(series, priors.params)
    assert result.status["max_yaw_rate"] == PRIOR
    assert result.params.max_yaw_rate == pytest.approx(math.radians(100.0))
    assert result.status["max_speed"] == PRIOR
    assert result.params.max_speed == pytest.approx(5.0)
    assert result.status["turn_speed_coupling"] in (PRIOR, BOUND)
    assert {"max_speed", "max_yaw_rate"} <= set(result.undetermined)
    # What the steps do show is still found.
    assert within(result.params.max_accel, TRUE.max_accel, 0.1)
    assert "max_accel" not in result.undetermined


def test_a_prior_the_log_contradicts_becomes_the_bound_the_log_allows():
    # Top speed prior 2 m/s, but the vehicle is seen at 3.3 m/s without reaching its clamp.
    series = synthetic(TRUE.with_(max_speed=6.0, turn_speed_coupling=0.0), 40.0,
                       speed_amp=3.4, rate_amp=0.3, seed=3)
    priors = ardupilot.priors({"CRUISE_SPEED": 1.0, "CRUISE_THROTTLE": 50.0})
    result = fit(series, priors.params)
    assert result.status["max_speed"] == BOUND
    assert 3.2 <= result.params.max_speed <= 4.5
    assert result.speed_rms < 0.03


# --------------------------------------------------------------------------- the manoeuvre, pure

@pytest.mark.parametrize("space", [5.0, 10.0])
def test_excitation_stays_within_space_and_shows_every_limit(space):
    model = RoverModel(TRUE)
    state = RoverState(x=3.0, y=-2.0, yaw=1.0)
    plan = Plan(space=space, max_speed=4.2, max_yaw_rate=2.4, decel=1.0)
    tracker = Excitation(plan)
    home = Reference(3.0, -2.0)
    cmds, far = [], 0.0
    t = 0.0
    for _ in range(int(85.0 / 0.025)):
        cmd = tracker.step(t, model.measure(state), home)
        cmds.append((cmd.speed, cmd.yaw_rate))
        for _ in range(25):
            state = model.step(state, cmd.speed, cmd.yaw_rate, 0.001)
        far = max(far, math.hypot(state.x - 3.0, state.y + 2.0))
        t += 0.025
    c = np.array(cmds)
    assert far <= space
    assert np.abs(c[:, 0]).max() <= plan.max_speed and np.abs(c[:, 1]).max() <= plan.max_yaw_rate
    assert c[:, 1].max() == plan.max_yaw_rate and c[:, 1].min() == -plan.max_yaw_rate
    assert c[:, 0].min() < -0.5                                # reversing
    assert np.any((np.abs(c[:, 0]) > 1.5) & (np.abs(c[:, 1]) == plan.max_yaw_rate))  # coupling
    # The script got to its turns at full speed (in 5 m the returns take longer than in 10 m,
    # where it runs to its end), and, when it ended, the rover stands at home.
    labels = [seg.label for seg in tracker.segments]
    assert tracker.index > labels.index("coupling: figure eight at full speed")
    if tracker.phase == "done":
        assert math.hypot(state.x - 3.0, state.y + 2.0) < 1.0 and abs(state.v) < 0.05
    assert space < 10 or tracker.phase == "done"


# --------------------------------------------------------------------------- real logs

@pytest.fixture(scope="module")
def vehicle_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("vehicle") / "true.toml"
    save(VehicleFile(params=TRUE, name="test vehicle"), path)
    return path


def check_recovered(params: dict, rel: float = 0.15,
                    turning_speeds: tuple[float, float] | None = None) -> None:
    """The identified file's figures against TRUE, for what any log of ours excites.

    ``turning_speeds`` (m/s, low and high): the log turned at its limit only at those speeds;
    the top turn rate there (``max_yaw_rate`` x (1 - ``speed_turn_coupling`` x v /
    ``max_speed``)) is checked instead of the clamp and its loss with speed apart. Why: the
    fit's three chains do not always find the best of that valley on such a log. One log of the
    failsafe test below (a loaded machine moves where its stop falls) fitted 2.51 rad/s with
    coupling 0.39, turn-rate RMS 0.018 rad/s, where TRUE's 2.0 and 0.15 give 0.011 and seed 1
    or six chains find 1.93-2.16 (0.009): the same top turn rate within 8 % from 2.1 to 3.3
    m/s. (docs/calibrate-and-identify.md, "what the fit can miss".)"""
    s, w = params["speed"], params["turn_rate"]
    assert within(s["accel_max_m_s2"], TRUE.max_accel, rel), s
    assert within(w["accel_max_rad_s2"], TRUE.max_yaw_accel, rel), w
    if turning_speeds is None:
        assert within(w["max_rad_s"], TRUE.max_yaw_rate, rel), w
    else:
        fitted = RoverModel(TRUE.with_(max_yaw_rate=w["max_rad_s"], max_speed=s["max_m_s"],
                                       speed_turn_coupling=params["coupling"]["speed_turn"]))
        for v in turning_speeds:
            top, truth = fitted.tops(0.0, v)[1], RoverModel(TRUE).tops(0.0, v)[1]
            assert within(top, truth, rel), (v, top, truth, params["coupling"], w)
    assert abs(w["delay_s"] - TRUE.yaw_delay) <= 0.05, w


def turning_speeds(csv_path: str, limit: float) -> tuple[float, float]:
    """The 5th and 95th percentile of the speed (m/s, the flight log's, from its tracked
    positions) while the companion's turn-rate command sat at ``limit``: where the log shows
    the turn clamp."""
    flight = read_csv(csv_path)
    at_limit = np.abs(flight.yaw_rate_cmd) >= limit - 1e-6
    v = np.interp(flight.cmd_t[at_limit], flight.t, flight.speed)
    assert v.size > 100, "the log never turned at its limit"
    lo, hi = np.percentile(v, [5, 95])
    return float(lo), float(hi)


def test_identify_a_companion_run_log_end_to_end(vehicle_file, tmp_path):
    mission = ellipse_mission(tmp_path / "ellipse.toml", 40.0, f_r=0.12)
    logs = tmp_path / "logs"
    with PlantProcess("--lockstep", "--vehicle", str(vehicle_file)) as plant:
        run = companion("run", "--connect", f"udpin:127.0.0.1:{plant.port}", "--arm", "--json",
                        "-q", "--no-zenoh", "--mission", str(mission), "--log-dir", str(logs),
                        "--max-yaw-rate", "3")
    assert run.returncode == 0, run.stderr
    flown = json.loads(run.stdout.strip().splitlines()[-1])
    out, plots = tmp_path / "vehicle.toml", tmp_path / "plots"
    p = companion("identify", flown["tlog"], "--out", str(out), "--check", flown["csv"],
                  "--plot", str(plots), "--json")
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    check_recovered(r["params"])
    assert r["rms"]["speed_m_s"] < 0.05 and r["rms"]["yaw_rate_rad_s"] < 0.05
    assert r["check"]["log"] == flown["csv"] and r["check"]["yaw_rate_rad_s"] < 0.15
    assert r["out"] == str(out)
    assert set(r["undetermined"]) == {k for k, v in r["status"].items() if v != "fitted"}
    written = load(out)
    # (the file keeps 6 significant digits)
    assert written.params.max_accel == pytest.approx(r["params"]["speed"]["accel_max_m_s2"],
                                                     rel=1e-5)
    assert written.fit["speed_rms_m_s"] == pytest.approx(r["rms"]["speed_m_s"], rel=1e-5)
    assert "check_yaw_rate_rms_rad_s" in written.fit and written.source["log"] == flown["tlog"]
    header = out.read_text().splitlines()[0]
    assert header.startswith("# pzc-rover vehicle file, written by `companion identify ")
    assert flown["tlog"] in header
    assert all(Path(f).stat().st_size > 10_000 for f in r["figures"]) and len(r["figures"]) == 2
    # The plain-text report says the same, and names what the log left undetermined.
    text = companion("identify", flown["tlog"], "--out", str(tmp_path / "again.toml"))
    assert text.returncode == 0 and "RMS         speed" in text.stdout
    assert "undetermined" in text.stdout
    # Several logs are fitted together, and the file says which.
    both = companion("identify", flown["tlog"], flown["csv"], "--out", str(tmp_path / "j.toml"),
                     "--json")
    assert both.returncode == 0, both.stderr
    j = json.loads(both.stdout)
    assert j["log"] == f"{flown['tlog']} + {flown['csv']}" and j["samples"] > r["samples"]
    assert f"fitted to {flown['tlog']} + {flown['csv']}" in (tmp_path / "j.toml").read_text()
    check_recovered(j["params"])


def _pause_when_tracked(plant: PlantProcess, logs: Path, mission_s: float, pause: float,
                        deadline: float) -> bool:
    """Stop the plant process (SIGSTOP) for ``pause`` wall s once the companion's CSV shows
    ``mission_s`` of mission tracked: a vehicle that falls silent mid-flight, as a descheduled
    autopilot or a dead link does. True when it was paused."""
    while time.monotonic() < deadline:
        for path in logs.glob("*.csv"):
            rows = path.read_text(errors="replace").splitlines()[1:]
            if any(r.split(",")[1:2] not in ([""], []) and float(r.split(",")[1]) >= mission_s
                   for r in rows[-5:] if not r.split(",")[-1]):
                os.kill(plant.proc.pid, signal.SIGSTOP)
                try:
                    time.sleep(pause)
                finally:
                    os.kill(plant.proc.pid, signal.SIGCONT)
                return True
        time.sleep(0.02)
    return False


def test_a_run_log_with_a_failsafe_in_it_records_the_stop_and_still_identifies(vehicle_file,
                                                                                tmp_path):
    # (CI: a loaded machine descheduled the plant for over the 0.5 s stale timeout mid-flight;
    # the CSV then held the tracker's last setpoint through the stop and the re-engagement,
    # and the model "missed" it by 0.3 rad/s RMS)
    mission = ellipse_mission(tmp_path / "ellipse.toml", 40.0, f_r=0.12)
    logs = tmp_path / "logs"
    with PlantProcess("--lockstep", "--vehicle", str(vehicle_file)) as plant:
        run = subprocess.Popen(
            [sys.executable, "-m", "companion", "run", "--connect",
             f"udpin:127.0.0.1:{plant.port}", "--arm", "--json", "-q", "--no-zenoh",
             "--mission", str(mission), "--log-dir", str(logs), "--max-yaw-rate", "3"],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            paused = _pause_when_tracked(plant, logs, 15.0, 1.0, time.monotonic() + 120.0)
            out, err = run.communicate(timeout=240.0)
        finally:
            if run.poll() is None:
                run.kill()
                run.wait()
    assert paused and run.returncode == 0, err
    flown = json.loads(out.strip().splitlines()[-1])
    assert flown["reason"] == "mission_done" and flown["failsafes"] >= 1, flown
    # The failsafe's row carries the zero setpoint it sent, at the last sample heard.
    stops = [r for r in Path(flown["csv"]).read_text().splitlines()
             if "failsafe: telemetry stale" in r.split(",")[-1]]
    assert stops, "no failsafe row in the CSV"
    cells = dict(zip(CSV_FIELDS, stops[0].split(","), strict=True))
    assert cells["speed_cmd"] == cells["yaw_rate_cmd"] == "0" and cells["vehicle_time"]
    p = companion("identify", flown["tlog"], "--out", str(tmp_path / "v.toml"), "--check",
                  flown["csv"], "--json")
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    check_recovered(r["params"], turning_speeds=turning_speeds(flown["csv"], 3.0))
    # Holding the tracker's setpoint through the stop made these 0.18 m/s and 0.29-0.31 rad/s.
    # With the stop recorded the speed is 0.007-0.044 m/s (2026-12-07: five runs alone, four
    # side by side) and 0.063 once in a fresh clone's `make test`: the SIGSTOP lands at a
    # different point of the lockstep exchange each time, so the rover coasts differently
    # through the 0.6 s before tracking resumes. 0.1 still tells the two apart.
    assert r["check"]["speed_m_s"] < 0.1 and r["check"]["yaw_rate_rad_s"] < 0.15, r["check"]


@pytest.mark.slow   # long: started first under workers (conftest.py)
def test_live_identify_stays_within_space_ends_in_hold_and_writes_the_file(vehicle_file,
                                                                         tmp_path):
    out, logs = tmp_path / "live.toml", tmp_path / "logs"
    with PlantProcess("--lockstep", "--vehicle", str(vehicle_file),
                      "--start", "4", "-3", "2.0") as plant:
        p = companion("identify", "--connect", f"udpin:127.0.0.1:{plant.port}", "--arm",
                      "--space", "6", "--out", str(out), "--json", "--no-zenoh",
                      "--log-dir", str(logs), timeout=240.0)
        # The vehicle's own word, after the companion has gone: it is in HOLD.
        with Pilot(plant.port) as pilot:
            assert pilot.wait("HEARTBEAT", 5.0).custom_mode == 4
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    flight = r["flight"]
    assert flight["reason"] == "mission_done" and flight["hold_confirmed"]
    assert flight["duration_s"] <= 90.0
    assert flight["max_distance_m"] <= 6.0
    check_recovered(r["params"], rel=0.1)
    assert within(r["params"]["speed"]["decel_max_m_s2"], TRUE.decel, 0.1)
    assert within(r["params"]["turn_rate"]["decel_max_rad_s2"], TRUE.yaw_decel, 0.1)
    assert abs(r["params"]["speed"]["delay_s"] - TRUE.speed_delay) <= 0.05
    assert r["rms"]["speed_m_s"] < 0.05 and r["rms"]["yaw_rate_rad_s"] < 0.05
    # Independently of the companion: the vehicle's own reports in the log.
    frames, bad = read_tlog(Path(flight["tlog"]))
    assert bad == 0
    poses = [(m.x, m.y) for _, m in frames if m.get_type() == "LOCAL_POSITION_NED"]
    x0, y0 = poses[0]
    assert max(math.hypot(x - x0, y - y0) for x, y in poses) <= 6.0
    asked = {m.param_id for _, m in frames if m.get_type() == "PARAM_REQUEST_READ"}
    assert {"ATC_ACCEL_MAX", "ATC_STR_ACC_MAX", "ATC_STR_RAT_MAX"} <= asked
    written = load(out)
    assert written.params.max_yaw_accel == pytest.approx(
        r["params"]["turn_rate"]["accel_max_rad_s2"], rel=1e-5)
    assert "--connect" in written.source["command"] and written.source["log"] == flight["tlog"]
    # the file names the profiles that fly it: the heartbeat's autopilot, the frame's kind
    assert (written.autopilot, written.steering) == ("ardupilot", "skid")


def test_live_identify_ends_when_the_manoeuvre_script_does(tmp_path):
    """PX4's velocity-vector script is over in about a minute: the flight ends there, in Hold,
    not after the identify mission's 85 s of the rover standing still (which only cost
    calibrate's time)."""
    vehicle = tmp_path / "px4.toml"
    save(VehicleFile(RoverParams(w_c=4.0, w_c_yaw=20.0, speed_delay=0.1, yaw_delay=0.04,
                                 max_speed=3.0, max_accel=3.0, max_yaw_rate=math.pi,
                                 max_yaw_accel=7.0, course_gain=5.0, min_turn_radius=0.556),
                     name="px4-like"), vehicle)
    out, logs = tmp_path / "live.toml", tmp_path / "logs"
    with PlantProcess("--lockstep", "--autopilot", "px4", "--vehicle", str(vehicle)) as plant:
        p = companion("identify", "--connect", f"udpin:127.0.0.1:{plant.port}", "--arm",
                      "--space", "10", "--out", str(out), "--json", "--no-zenoh",
                      "--log-dir", str(logs), timeout=240.0)
    assert p.returncode == 0, p.stderr
    flight = json.loads(p.stdout)["flight"]
    assert flight["reason"] == "mission_done" and flight["hold_confirmed"], flight
    assert 45.0 < flight["duration_s"] < 75.0, flight
    events = [row["event"] for row in csv.DictReader(open(flight["csv"])) if row["event"]]
    assert any("the script is over" in e for e in events), events
    assert load(out).params.velocity_vector
    assert load(out).autopilot == "px4"            # from the log's heartbeat, named in the file


def _stop_identify_mid_manoeuvre(plant_port: int, args: list[str], stop) -> str:
    """``companion identify`` on the plant with ``args``; 3 s into the manoeuvre ``stop(proc)``
    asks it to stop. Its stderr, once it has ended with exit 0 and no traceback."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "companion", "identify", "--connect",
         f"udpin:127.0.0.1:{plant_port}", "--arm", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        seen = ""
        while "tracking 'identify excitation'" not in seen:
            line = proc.stderr.readline()
            assert line, f"identify ended before tracking:\n{seen}"
            seen += line
        time.sleep(3.0)
        stop(proc)
        _, err = proc.communicate(timeout=15.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0 and "Traceback" not in err, err
    return err


def test_sigterm_stops_the_manoeuvre_in_hold_and_fits_nothing(vehicle_file, tmp_path):
    out = tmp_path / "v.toml"
    with PlantProcess("--speedup", "2", "--vehicle", str(vehicle_file)) as plant:
        err = _stop_identify_mid_manoeuvre(
            plant.port, ["--out", str(out), "--no-zenoh", "--log-dir", str(tmp_path / "logs")],
            lambda proc: proc.send_signal(signal.SIGTERM))
        assert "stopped by SIGTERM before the manoeuvre ended: not fitted" in err
        with Pilot(plant.port) as pilot:
            assert pilot.wait("HEARTBEAT", 5.0).custom_mode == 4          # HOLD
            speeds = [math.hypot(m.vx, m.vy) for m in
                      pilot.collect(("LOCAL_POSITION_NED",), 3.0)[-10:]]
            assert max(speeds) < 0.05
    assert not out.exists()


def test_an_abort_from_the_control_channel_stops_the_manoeuvre_and_fits_nothing(vehicle_file,
                                                                             tmp_path):
    """``abort`` over Zenoh mid-manoeuvre is a stop asked for, as SIGTERM is: HOLD, exit 0,
    said as an abort request, and half a manoeuvre is not fitted into a vehicle file."""
    from companion.bus.control_client import control_request
    from testbed.zenoh_fleet import ISOLATED, endpoint, free_tcp_port, secret_file, session
    out, port = tmp_path / "v.toml", free_tcp_port()
    key = secret_file(tmp_path / "secret")
    replies = []

    def abort(proc) -> None:
        replies.append(control_request(zs, "id1", "abort", secret="correct horse battery staple",
                                       timeout=5.0))

    with session(listen=[endpoint(port)]) as zs, \
            PlantProcess("--speedup", "2", "--vehicle", str(vehicle_file)) as plant:
        err = _stop_identify_mid_manoeuvre(
            plant.port, ["--out", str(out), "--vehicle-id", "id1", "--control-secret", str(key),
                         "--zenoh-connect", endpoint(port), *ISOLATED,
                         "--log-dir", str(tmp_path / "logs")], abort)
        assert replies[0]["ok"] and replies[0]["message"] == "stopping the rover", replies
        assert "stopped by an abort request before the manoeuvre ended: not fitted" in err, err
        with Pilot(plant.port) as pilot:
            assert pilot.wait("HEARTBEAT", 5.0).custom_mode == 4          # HOLD
    assert not out.exists()


def test_a_pilot_takeover_ends_the_manoeuvre_and_what_was_flown_is_fitted(vehicle_file,
                                                                          tmp_path):
    out, port = tmp_path / "v.toml", free_udp_port()
    # identify first, the plant once it listens: the takeover is at 30 s of the plant's clock,
    # which starts at its boot, and the turn-rate part must be flown by then however long
    # identify took to start on a loaded machine
    with Companion(port, "--arm", "--out", str(out), "--json", "--no-zenoh", "--no-log",
                   command="identify") as p:
        p.wait_bound(port)
        with PlantProcess("--lockstep", "--vehicle", str(vehicle_file), "--takeover-at", "30",
                          port=port):
            code = p.wait(240.0)
    assert code == 4, p.stderr
    r = json.loads(p.stdout)
    assert r["flight"]["reason"].startswith("pilot_override")
    assert r["flight"]["tlog"] is None and r["log"].startswith("the manoeuvre flown")
    # The turn-rate part was flown before the pilot took over: its limits are found.
    assert within(r["params"]["turn_rate"]["accel_max_rad_s2"], TRUE.max_yaw_accel, 0.1)
    assert load(out).fit["samples"] == r["samples"]


# --------------------------------------------------------------------------- one-line errors

def _tlog(path: Path, messages) -> Path:
    """A .tlog as pymavlink writes one: 8-byte big-endian microseconds, then the frame."""
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    with open(path, "wb") as f:
        for k, msg in enumerate(messages):
            f.write(struct.pack(">Q", 1_700_000_000_000_000 + 25_000 * k) + msg.pack(mav))
    return path


def test_a_log_without_setpoints_is_one_line(tmp_path):
    msgs = [mavlink2.MAVLink_heartbeat_message(10, 3, 0, 0, 0, 3)]
    for k in range(400):
        msgs.append(mavlink2.MAVLink_attitude_message(1000 + 25 * k, 0, 0, 0.1, 0, 0, 0))
        msgs.append(mavlink2.MAVLink_local_position_ned_message(1000 + 25 * k, 0.01 * k, 0, 0,
                                                                0.4, 0, 0))
    log = _tlog(tmp_path / "telemetry_only.tlog", msgs)
    one_line_error(companion("identify", str(log), "--out", str(tmp_path / "v.toml")),
                   "no setpoints")
    assert not (tmp_path / "v.toml").exists()


def test_a_too_short_log_is_one_line(tmp_path):
    rows = [",".join(CSV_FIELDS)]
    for k in range(30):
        t = 0.025 * k
        numeric = [t, t, 0.5 * t, 0, 0, 0.5 * t, 0, 0, 0, 0, 0, 0, 0.5, 0, 0.5, 0.1]
        rows.append(",".join(f"{v:g}" for v in numeric) + ",GUIDED,1,,")
    log = tmp_path / "short.csv"
    log.write_text("\n".join(rows) + "\n")
    one_line_error(companion("identify", str(log), "--out", str(tmp_path / "v.toml")),
                   "too short")


def test_malformed_logs_are_one_line(tmp_path):
    garbage = tmp_path / "garbage.tlog"
    garbage.write_bytes(bytes(range(256)) * 40)
    one_line_error(companion("identify", str(garbage), "--out", str(tmp_path / "v.toml")),
                   "garbage.tlog")
    not_ours = tmp_path / "other.csv"
    not_ours.write_text("time,lat,lon\n1,2,3\n")
    one_line_error(companion("identify", str(not_ours), "--out", str(tmp_path / "v.toml")),
                   "not a companion flight-log CSV")
    one_line_error(companion("identify", str(tmp_path / "missing.tlog"), "--out",
                             str(tmp_path / "v.toml")), "no such file")


def test_log_or_connect_and_a_writable_out(tmp_path):
    one_line_error(companion("identify", "--out", str(tmp_path / "v.toml")), "one of them")
    one_line_error(companion("identify", "x.tlog", "--connect",
                             f"udpin:127.0.0.1:{free_udp_port()}", "--out", "v.toml"),
                   "one of them")
    one_line_error(companion("identify", "x.tlog", "--out", str(tmp_path / "no/dir/v.toml")),
                   "no such directory")


# --------------------------------------------------------------------------- the real autopilot

@pytest.mark.sitl
@pytest.mark.slow
@CANDIDATE   # 9 of 10 on 2026-12-02: yaw-rate fit 0.18 rad/s once at 5 x real time, load 6
def test_live_identify_on_ardupilot_sitl_finds_its_own_limits(ardupilot, tmp_path):
    """Stock rover-skid at 5 x real time: the manoeuvre within 10 m, HOLD at the end, and the
    acceleration and turn-rate acceleration limits within 15 % of ArduPilot's (ATC_ACCEL_MAX 1
    m/s^2, ATC_STR_ACC_MAX 120 deg/s^2), read from the vehicle as priors."""
    sitl = ardupilot(speedup=5)
    out = tmp_path / "skid.toml"
    p = companion("identify", "--connect", sitl.url(0), "--arm", "--out", str(out), "--json",
                  "--no-zenoh", "--log-dir", str(tmp_path / "logs"), timeout=300.0)
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    assert r["flight"]["reason"] == "mission_done" and r["flight"]["hold_confirmed"]
    assert r["flight"]["max_distance_m"] <= 10.0
    assert r["autopilot_params"]["ATC_ACCEL_MAX"] == 1.0
    assert within(r["params"]["speed"]["accel_max_m_s2"], 1.0, 0.15)
    assert within(r["params"]["turn_rate"]["accel_max_rad_s2"], math.radians(120.0), 0.15)
    assert r["rms"]["speed_m_s"] < 0.1 and r["rms"]["yaw_rate_rad_s"] < 0.1
    assert load(out).source["ATC_STR_ACC_MAX"] == 120.0


@functools.lru_cache(maxsize=1)
def turning_and_driving():
    """A flight turning on the spot and one driving straight, fitted together (two tests)."""
    turning = synthetic(TRUE, 33.0, speed_amp=0.0, rate_amp=2.6, seed=3, stop=3.0)
    driving = synthetic(TRUE, 33.0, speed_amp=4.5, rate_amp=0.0, seed=4, stop=3.0)
    series = join([turning, driving])
    return turning, driving, series, fit(series, defaults())


def test_each_fitted_parameter_says_how_tightly_and_by_which_log_it_is_determined():
    # joined: the turning flight alone determines the turn-rate limits, the driving flight
    # the speed limits; each range holds the truth's neighbourhood and is finite where the
    # log bounds both sides (a rate limit the log reaches over and over)
    _, _, _, result = turning_and_driving()
    det = result.determined
    assert set(det) == {n for n, s in result.status.items() if s == FITTED}
    for name, log in (("max_yaw_accel", 0), ("max_accel", 1)):
        d, value = det[name], getattr(result.params, name)
        assert d.logs == (log,), (name, d)
        assert d.lo <= value <= d.hi and math.isfinite(d.lo) and math.isfinite(d.hi)
        assert d.hi / d.lo < 1.3                      # pinned to within tens of percent
        assert d.lo <= getattr(TRUE, name) * 1.05 and d.hi >= getattr(TRUE, name) * 0.95


def test_the_vehicle_file_records_what_each_log_determined(tmp_path):
    from companion.ident.priors import Priors
    from companion.ident.record import Report, determined
    from companion.ident.record import vehicle_file as to_file
    turning, driving, series, result = turning_and_driving()
    report = Report(result, Priors(defaults(), {}), series, "/logs/turn.tlog + /logs/drive.tlog",
                    1.0, parts=[turning, driving])
    table = determined(report)
    assert table["speed.accel_max_m_s2"]["logs"] == ["drive.tlog"]
    assert table["turn_rate.accel_max_rad_s2"]["logs"] == ["turn.tlog"]
    save(to_file(report, "t"), tmp_path / "v.toml")
    back = load(tmp_path / "v.toml").determined
    assert back["speed_accel_max_m_s2"].startswith("fitted ")
    assert "by drive.tlog" in back["speed_accel_max_m_s2"]
    assert " to " in back["turn_rate_accel_max_rad_s2"]
