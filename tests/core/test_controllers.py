"""The tracker protocol and the controller registry: every registered controller keeps the
contract of :mod:`companion.core.tracker` on one vehicle and on many, Kanayama's law has its
feed-forward, and ``simulate`` and the live loop build the same tracker for the same name."""

from __future__ import annotations

import json
import math
import subprocess

import numpy as np
import pytest

from companion.core import controllers
from companion.core.filter import FilterGains
from companion.core.limits import Limits
from companion.core.signals import Command, Estimate, Measurement
from companion.core.tracker import Tracker
from companion.core.trajectory import Ellipse
from testbed.process import companion_cli

LIMITS = Limits(max_speed=4.0, max_yaw_rate=3.0)


def _inputs(k: int, n: int | None = None):
    """The k-th control step at 40 Hz: a rover on a circle of radius 2, the paper's ellipse
    as the reference (arrays of n slightly different vehicles when n is given)."""
    t = k / 40.0
    shift = 0.0 if n is None else np.linspace(0.0, 0.3, n)
    meas = Measurement(2.0 * math.cos(0.3 * t) + shift, 2.0 * math.sin(0.3 * t) - shift,
                       0.3 * t + math.pi / 2 + shift, -0.6 * math.sin(0.3 * t) + 0 * shift,
                       0.6 * math.cos(0.3 * t) + 0 * shift, 0.3 + 0 * shift)
    f_r = 0.04 if n is None else np.full(n, 0.04)
    return t, meas, Ellipse.paper(f_r).sample(t)


def _fly(tracker, steps: int, n: int | None = None) -> list[Command]:
    return [tracker.step(*_inputs(k, n)) for k in range(steps)]


def test_the_registry_names_the_three_controllers_pzc_first():
    assert controllers.NAMES == ("pzc", "pid", "kanayama")
    assert controllers.DEFAULT == "pzc"
    assert controllers.get("pzc").uses_pzc_gains
    assert not controllers.get("pid").uses_pzc_gains
    with pytest.raises(ValueError, match="unknown controller 'lqr'; choose one of pzc, pid"):
        controllers.get("lqr")
    # a baseline given PZC gains would silently fly its own: refused
    with pytest.raises(ValueError, match="flies its own gains"):
        controllers.build("pid", LIMITS, filter_gains=FilterGains())


@pytest.mark.parametrize("name", controllers.NAMES)
def test_every_controller_keeps_the_tracker_contract_on_one_vehicle(name):
    tracker = controllers.build(name, LIMITS)
    assert isinstance(tracker, Tracker) and tracker.name == name
    assert tracker.estimate is None                       # before the first step
    first = _fly(tracker, 80)
    est = tracker.estimate
    assert isinstance(est, Estimate) and all(isinstance(getattr(est, f), float)
                                             for f in ("x", "y", "yaw"))
    for cmd in first:
        assert isinstance(cmd.speed, float) and isinstance(cmd.yaw_rate, float)
        assert abs(cmd.speed) <= LIMITS.max_speed and abs(cmd.yaw_rate) <= LIMITS.max_yaw_rate
        assert math.hypot(cmd.ux, cmd.uy) <= LIMITS.max_speed + 1e-12
    # reset forgets everything: the same inputs give the same commands as from new
    tracker.reset()
    assert tracker.estimate is None
    again = _fly(tracker, 80)
    assert [(c.speed, c.yaw_rate, c.ux, c.uy) for c in again] == \
        [(c.speed, c.yaw_rate, c.ux, c.uy) for c in first]


@pytest.mark.parametrize("name", controllers.NAMES)
def test_every_controller_runs_vectorised_and_agrees_with_one_vehicle(name):
    n = 3
    many = controllers.build(name, LIMITS, n=n)
    assert isinstance(many, Tracker) and many.estimate is None
    cmds = _fly(many, 60, n)
    assert many.estimate.x.shape == (n,) and cmds[-1].speed.shape == (n,)
    for i in range(n):
        one = controllers.build(name, LIMITS)
        for k, cmd in enumerate(cmds):
            t, meas, ref = _inputs(k, n)
            pick = lambda s, i=i: type(s)(*[float(getattr(s, f)[i]) for f in s.__slots__])  # noqa: E731
            c1 = one.step(t, pick(meas), pick(ref))
            assert c1.speed == pytest.approx(float(cmd.speed[i]), rel=1e-9, abs=1e-12)
            assert c1.yaw_rate == pytest.approx(float(cmd.yaw_rate[i]), rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("name", ["pid", "kanayama"])
def test_a_baseline_flies_the_raw_measurement_as_its_estimate(name):
    tracker = controllers.build(name, LIMITS)
    t, meas, ref = _inputs(5)
    tracker.step(t, meas, ref)
    est = tracker.estimate
    assert (est.x, est.y, est.yaw, est.vx, est.vy, est.yaw_rate) == \
        (meas.x, meas.y, meas.yaw, meas.vx, meas.vy, meas.yaw_rate)


def test_kanayama_feeds_the_reference_speed_and_turn_rate_forward():
    """On the reference exactly (x_e = y_e = theta_e = 0) Kanayama's law is pure feed-forward:
    v = v_r, omega = omega_r; a lateral error y_e turns it by v_r K_y y_e."""
    tracker = controllers.build("kanayama")
    ref = Ellipse.paper(0.08).sample(3.0)
    v_r = math.hypot(ref.vx, ref.vy)
    theta_r = math.atan2(ref.vy, ref.vx)
    omega_r = (ref.vx * ref.ay - ref.vy * ref.ax) / v_r ** 2
    on = tracker.step(3.0, Measurement(ref.x, ref.y, theta_r), ref)
    assert on.speed == pytest.approx(v_r, rel=1e-12)
    assert on.yaw_rate == pytest.approx(omega_r, rel=1e-12)
    assert abs(omega_r) > 0.05 and v_r > 1.0             # both terms really are there
    # 0.1 m to the reference's right (the reference lies to the vehicle's left: y_e = +0.1)
    off = tracker.step(3.025, Measurement(ref.x + 0.1 * math.sin(theta_r),
                                          ref.y - 0.1 * math.cos(theta_r), theta_r), ref)
    gains = controllers.get("kanayama").default_gains
    assert off.yaw_rate - omega_r == pytest.approx(v_r * gains.ky * 0.1, rel=1e-9)


@pytest.mark.parametrize("name", controllers.NAMES)
def test_simulate_and_the_live_loop_build_the_same_tracker(name):
    """``companion simulate`` and ``companion run`` / ``demo`` (live.session) build their
    trackers through the registry: the same name, mission and rate give the same tracker,
    which answers the same inputs with the same commands."""
    from companion.live import policy
    from companion.mission import paper_ellipse

    mission = paper_ellipse()
    options = policy.GainOptions(max_speed=LIMITS.max_speed, max_yaw_rate=LIMITS.max_yaw_rate)
    # simulate: resolve() before anything; the live loop: choose_gains() at the accepted rate
    resolved = policy.resolve(mission, options)
    sim, sim_gains, sim_source = policy.build_tracker(name, resolved.gains, resolved.limits)
    choice = policy.choose_gains(mission, options, policy.KnownVehicle(), resolved.rate)
    live, live_gains, live_source = policy.build_tracker(name, choice, resolved.limits)
    assert type(sim) is type(live) and sim.name == live.name == name
    assert sim_gains == live_gains and sim_source == live_source
    if name != "pzc":
        assert sim_source == controllers.get(name).defaults_source()
    a, b = _fly(sim, 120), _fly(live, 120)
    assert [(c.speed, c.yaw_rate) for c in a] == [(c.speed, c.yaw_rate) for c in b]


@pytest.mark.parametrize("command", ["run", "demo", "simulate"])
def test_controller_flag_offers_the_registry_and_refuses_others(command):
    help_text = companion_cli(command, "--help", timeout=60).stdout
    assert "--controller {pzc,pid,kanayama}" in help_text
    extra = ["--mission", "missions/paper_ellipse_004.toml"] if command == "run" else []
    p = companion_cli(command, *extra, "--controller",
                      "lqr", timeout=60)
    assert p.returncode == 2 and "invalid choice: 'lqr'" in p.stderr
    assert "Traceback" not in p.stderr


def test_pzc_gains_for_a_baseline_are_one_clear_line():
    p = companion_cli("simulate", "--controller", "pid",
                      "--gains", "companion/sim/tuned/rate40_wc20.toml", timeout=60)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert p.stderr.strip().splitlines() == [
        "companion simulate: error: --gains sets the filter + PZC gains; --controller pid "
        "flies its own gains (--controller-gains)"]


def test_pzc_gain_flags_for_a_baseline_on_run_are_refused_before_connecting():
    # nobody listens on the port: the refusal must come before any wait for a vehicle
    p = companion_cli("run", "--connect",
                      "udpin:127.0.0.1:9", "--mission", "missions/paper_ellipse_004.toml",
                      "--controller", "kanayama", "--k-dc", "2", "--lambda-c", "3",
                      "--no-log", timeout=60)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert p.stderr.strip().splitlines()[-1].endswith(
        "--k-dc and --lambda-c set the filter + PZC gains; --controller kanayama flies its own "
        "gains (--controller-gains)")


# --- --controller-gains: a baseline's own gains, set field by field -------------------------

SKID = "companion/sim/vehicles/ardupilot_skid.toml"


def _simulate(*args: str) -> subprocess.CompletedProcess:
    return companion_cli("simulate", *args, timeout=60)


def test_own_gains_are_set_field_by_field_over_the_defaults_and_reach_the_tracker():
    from companion.core.baselines import KanayamaGains, PIDGains
    kan, pid = controllers.get("kanayama"), controllers.get("pid")
    gains = kan.with_gains({"kx": 1.0, "kth": 1.2})
    assert gains == KanayamaGains(kx=1.0, ky=4.0, kth=1.2)         # ky stays at its default
    assert controllers.build("kanayama", LIMITS, own_gains=gains).gains is gains
    assert controllers.build("kanayama", LIMITS, own_gains=gains, n=3).gains is gains
    assert pid.with_gains({"ki": 0.0, "speed_law": "paper"}) == PIDGains(ki=0.0, speed_law="paper")
    assert kan.describe(gains, "--controller-gains") == (
        "kanayama --controller-gains (Kanayama et al. (1990), gains chosen by hand): "
        "kx 1, ky 4, kth 1.2")
    # the wrong kind of gains, or own gains for pzc, is refused rather than ignored
    with pytest.raises(ValueError, match="flies KanayamaGains, not PIDGains"):
        controllers.build("kanayama", LIMITS, own_gains=PIDGains())
    with pytest.raises(ValueError, match="none of its own"):
        controllers.build("pzc", LIMITS, own_gains=gains)


def test_the_live_loop_and_simulate_fly_the_gains_given():
    """policy.build_tracker (run, demo and simulate alike) flies ``--controller-gains`` and its
    result names them; check_controller refuses them for a controller they are not for."""
    from companion.errors import UserError
    from companion.live import policy
    from companion.mission import paper_ellipse

    own = controllers.get("kanayama").with_gains({"kx": 1.0, "ky": 0.5, "kth": 1.2})
    options = policy.GainOptions(controller_gains=own)
    policy.check_controller("kanayama", options)
    resolved = policy.resolve(paper_ellipse(), options)
    tracker, values, source = policy.build_tracker("kanayama", resolved.gains, LIMITS, own)
    assert tracker.gains is own and values == {"kx": 1.0, "ky": 0.5, "kth": 1.2}
    assert source.startswith("kanayama --controller-gains (") and source.endswith(
        ": kx 1, ky 0.5, kth 1.2")
    default = controllers.build("kanayama", LIMITS)
    assert [(c.speed, c.yaw_rate) for c in _fly(tracker, 40)] != \
        [(c.speed, c.yaw_rate) for c in _fly(default, 40)]
    for name in ("pzc", "pid"):
        with pytest.raises(UserError, match=f"--controller-gains .* --controller {name}"):
            policy.check_controller(name, options)


def test_simulate_flies_controller_gains_deterministically_and_shows_them():
    """Kanayama's defaults limit-cycle on the identified ArduPilot skid-steer (the yaw-rate
    setpoint at its limit); the gains picked for it (benchmarks/kanayama_gains.toml) track,
    the same every time, and the JSON names them."""
    base = ["--vehicle", SKID, "--mission", "missions/paper_ellipse_004.toml",
            "--controller", "kanayama", "--json"]
    flag = ["--controller-gains", "kx=1,ky=0.5,kth=1.2"]
    defaults, picked, again = (_simulate(*base), _simulate(*base, *flag),
                               _simulate(*base, *flag))
    for p in (defaults, picked, again):
        assert p.returncode == 0, p.stderr
    d, r, r2 = (json.loads(p.stdout) for p in (defaults, picked, again))
    assert d["gains"].startswith("kanayama defaults (") and d["gains_values"] == \
        {"kx": 3.0, "ky": 4.0, "kth": 3.0}
    assert r["gains"] == ("kanayama --controller-gains (Kanayama et al. (1990), gains chosen by "
                          "hand): kx 1, ky 0.5, kth 1.2")
    assert r["gains_values"] == {"kx": 1.0, "ky": 0.5, "kth": 1.2}
    assert r["steady_rms"] == r2["steady_rms"] and r["f_cost"] == r2["f_cost"]
    assert d["steady_rms"] > 1.0 and r["steady_rms"] < 0.1


def test_demo_flies_controller_gains_live(tmp_path):
    """The live loop (demo: the companion against the bundled plant over MAVLink) flies them
    too, and its result says so."""
    p = companion_cli("demo", "--json", "--controller",
                      "pid", "--controller-gains", "kp=2,kd=0", "--duration", "5",
                      "--no-plot", "--no-log", "-q", timeout=120)
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    assert r["controller"] == "pid" and r["reason"] == "mission_done"
    assert r["gains"] == {"kp": 2.0, "ki": 0.5, "kd": 0.0, "speed_law": "projected"}
    assert r["gains_source"].startswith("pid --controller-gains (")


@pytest.mark.parametrize("controller, value, message", [
    ("kanayama", "kz=1", "kanayama has no gain 'kz' (its gains: kx, ky, kth)"),
    ("kanayama", "kx=fast", "kx must be a number, not 'fast'"),
    ("kanayama", "kx=1,ky=0", "ky must be a finite number > 0, not 0"),
    ("kanayama", "kth=nan", "kth must be a finite number > 0, not nan"),
    ("kanayama", "kx=1,kx=2", "kx given twice"),
    ("kanayama", "kx", "'kx' is not NAME=VALUE (e.g. kx=1.5; kanayama's gains: kx, ky, kth)"),
    ("pid", "kd=-0.1", "kd must be a finite number >= 0, not -0.1"),
    ("pid", "speed_law=fast", "speed_law must be one of projected, paper, not 'fast'"),
])
def test_bad_controller_gains_are_one_line_naming_the_flag_and_the_field(controller, value,
                                                                          message):
    p = _simulate("--controller", controller, "--controller-gains", value)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert p.stderr.strip().splitlines() == [
        f"companion simulate: error: --controller-gains: {message}"]


@pytest.mark.parametrize("command", ["run", "simulate"])
def test_controller_gains_with_pzc_are_refused_before_anything_flies(command):
    extra = (["--connect", "udpin:127.0.0.1:9", "--mission", "missions/paper_ellipse_004.toml",
              "--no-log"] if command == "run" else [])
    p = companion_cli(command, *extra,
                      "--controller-gains", "kx=1", timeout=60)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert p.stderr.strip().splitlines()[-1] == (
        f"companion {command}: error: --controller-gains sets the own gains of a baseline "
        "(pid, kanayama); --controller pzc flies the filter + PZC gains (--gains, --k-df, "
        "--lambda-f, --k-dc, --lambda-c)")


@pytest.mark.parametrize("command", ["run", "demo", "simulate"])
def test_controller_gains_help_names_every_field(command):
    """The help text is built without importing the controllers (instant --help), so it names
    their fields itself: held here to the dataclasses."""
    help_text = " ".join(companion_cli(command, "--help", timeout=60).stdout.split())
    assert "--controller-gains NAME=VALUE[,...]" in help_text
    for name in ("pid", "kanayama"):
        fields = ", ".join(controllers.get(name).gain_defaults())
        assert f"{name}: {fields}" in help_text
