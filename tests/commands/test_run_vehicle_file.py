"""``companion run --vehicle FILE`` end to end: the gains tuned for that vehicle file (found beside
it), its limits on every setpoint, and the mission's ``[vehicle] file`` doing the same, against
``sitl-plant --vehicle FILE`` (the same identified model) over real UDP."""

from __future__ import annotations

import csv

from companion.app.vehicle import load
from companion.core.filter import FilterGains
from companion.core.pzc import PZCGains
from companion.sim import gains as gains_mod
from companion.sim import vehicle_file
from companion.sim.gains import TunedGains
from companion.sim.plant import RoverParams
from sitl_plant.testing import PlantProcess
from testbed.missions import ellipse_mission
from testbed.process import Companion

ROVER = RoverParams(w_c=1 / 0.13, w_c_yaw=1 / 0.05, max_speed=2.5, max_yaw_rate=1.5,
                    max_accel=1.0, max_yaw_accel=2.0, speed_delay=0.1, yaw_delay=0.05,
                    turn_speed_coupling=0.15)
GAINS = (FilterGains(600.0, 40.0), PZCGains(0.4, 0.8, k_dc_yaw=1.5, lambda_c_yaw=1.5,
                                            velocity_ff=True, heading_rate_ff=True))


def _vehicle_with_gains(folder):
    """A vehicle file and, beside it, gains recorded as tuned for exactly its bytes."""
    vpath = folder / "vehicle.toml"
    vehicle_file.save(vehicle_file.VehicleFile(ROVER, name="test rover"), vpath)
    tuned = TunedGains(*GAINS, rate_hz=40.0, w_c=float(ROVER.w_c), vehicle_file="vehicle.toml",
                       vehicle_sha256=load(vpath).sha256, header="made by the test")
    tuned.save(folder / "gains.toml")
    return vpath


def _fly(tmp_path, plant_vehicle, *companion_args):
    mission = ellipse_mission(tmp_path / "m.toml", 12.0, f_r=0.04)
    with PlantProcess("--lockstep", "--vehicle", str(plant_vehicle), "--tick-aligned") as plant, \
            Companion(plant.port, "--mission", str(mission), "--arm", "--json", "--no-zenoh",
                      "--log-dir", str(tmp_path / "logs"), *companion_args) as comp:
        assert comp.wait(90) == 0, comp.stderr
    return comp.result(), comp.stderr


def _speed_commands(csv_path):
    with open(csv_path) as f:
        return [abs(float(r["speed_cmd"])) for r in csv.DictReader(f) if r["speed_cmd"]]


def test_run_vehicle_flies_the_gains_tuned_for_it_within_its_limits(tmp_path):
    vpath = _vehicle_with_gains(tmp_path)
    r, stderr = _fly(tmp_path, vpath, "--vehicle", str(vpath))
    assert r["gains_source"] == f"vehicle {tmp_path / 'gains.toml'}"
    assert r["steady_rms"] < 0.5           # 12 s: still closing in on the reference
    speeds = _speed_commands(r["csv"])
    assert max(speeds) <= ROVER.max_speed + 1e-9 and max(speeds) > 2.0   # its limit, used
    # --gains still wins over the vehicle's own
    other = tmp_path / "other.toml"
    TunedGains(*GAINS, rate_hz=40.0, w_c=20.0).save(other)
    r, _ = _fly(tmp_path, vpath, "--vehicle", str(vpath), "--gains", str(other))
    assert r["gains_source"] == f"--gains {other}"


def test_a_missions_vehicle_file_is_used_like_run_vehicle(tmp_path):
    vpath = _vehicle_with_gains(tmp_path)
    mission = ellipse_mission(tmp_path / "m.toml", 12.0, f_r=0.04)
    mission.write_text(mission.read_text().replace(
        "[trajectory]", '[vehicle]\nfile = "vehicle.toml"\n\n[trajectory]'))
    with PlantProcess("--lockstep", "--vehicle", str(vpath), "--tick-aligned") as plant, \
            Companion(plant.port, "--mission", str(mission), "--arm", "--json", "--no-zenoh",
                      "--no-log") as comp:
        assert comp.wait(90) == 0, comp.stderr
    assert comp.result()["gains_source"] == f"vehicle {tmp_path / 'gains.toml'}"


def test_gains_for_another_vehicle_file_are_not_used(tmp_path):
    vpath = _vehicle_with_gains(tmp_path)
    vehicle_file.save(vehicle_file.VehicleFile(ROVER.with_(max_accel=0.5)), vpath)  # re-identified
    assert load(vpath).gains_at(40.0) is None
    assert gains_mod.load(tmp_path / "gains.toml").vehicle_sha256 != load(vpath).sha256


def test_the_shipped_preset_has_gains_tuned_for_it_and_the_demo_flies_them(tmp_path):
    import json
    import subprocess
    import sys

    from companion.sim.vehicle_file import preset_path
    from testbed.process import ROOT
    shipped = load(preset_path("ardupilot-skid")).gains_at(40.0)
    assert shipped is not None, "re-tune the preset's gains: its vehicle file changed"
    assert shipped.pzc.lead_tau == 0.0
    p = subprocess.run([sys.executable, "-m", "companion", "demo", "--preset", "ardupilot-skid",
                        "--duration", "10", "--json", "--no-plot", "--no-zenoh", "--no-log", "-q"],
                       capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout.splitlines()[-1])
    assert r["gains_source"] == f"vehicle {shipped.source}"
