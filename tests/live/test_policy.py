"""One policy for rate, gains and limits (companion.live.policy): ``simulate`` resolves what
``run`` flies, for the same mission, vehicle file and flags. ``run`` flies the bundled plant
over real UDP and reports what it used; ``simulate`` prints what it simulated with."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from companion import mission as missions
from companion.core.filter import FilterGains
from companion.core.limits import DEFAULT_LIMITS, Limits
from companion.core.pzc import PZCGains
from companion.live.policy import GainOptions, KnownVehicle, choose_limits, resolve
from companion.sim.gains import TunedGains
from sitl_plant.testing import PlantProcess
from testbed.missions import ellipse_mission
from testbed.process import Companion

ROOT = Path(__file__).resolve().parents[2]
SKID = ROOT / "companion" / "sim" / "vehicles" / "ardupilot_skid.toml"


def _simulate(*args: str) -> dict:
    proc = subprocess.run([sys.executable, "-m", "companion", "simulate", "--json", *args],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _run(tmp_path: Path, *args: str) -> dict:
    with PlantProcess("--lockstep", "--loop-rate", "100") as plant, \
            Companion(plant.port, "--arm", "--json", "--no-zenoh", "--no-log", *args) as comp:
        assert comp.wait(120) == 0, comp.stderr
    return comp.result()


@pytest.mark.parametrize("case", ["defaults", "vehicle file", "gains file and flags",
                                  "a baseline"])
def test_simulate_and_run_resolve_the_same_gains_and_limits(tmp_path, case):
    mission = ellipse_mission(tmp_path / "m.toml", 2.0, f_r=0.04)
    args = ["--mission", str(mission)]
    if case == "vehicle file":
        args += ["--vehicle", str(SKID)]
    elif case == "gains file and flags":
        gains = tmp_path / "g.toml"
        TunedGains(FilterGains(300.0, 30.0), PZCGains(0.7, 0.9, velocity_ff=True),
                   rate_hz=40.0, w_c=20.0).save(gains)
        args += ["--gains", str(gains), "--max-speed", "1.5", "--max-yaw-rate", "0.8"]
    elif case == "a baseline":
        args += ["--controller", "pid", "--vehicle", str(SKID)]
    ran = _run(tmp_path, *args)
    sim = _simulate(*args)
    assert sim["rate_hz"] == ran["rate_accepted_hz"] == 40.0
    assert sim["gains"] == ran["gains_source"]
    assert sim["gains_values"] == ran["gains"]
    assert sim["limits"] == ran["limits"]
    if case == "gains file and flags":
        assert ran["limits"] == {"max_speed": 1.5, "max_yaw_rate": 0.8}
        assert ran["gains"]["k_df"] == 300.0
    if case == "vehicle file":
        assert ran["gains_source"].startswith("vehicle ")
    if case == "a baseline":
        assert ran["controller"] == sim["controller"] == "pid"
        assert ran["gains_source"].startswith("pid defaults")
        assert ran["limits"]["max_speed"] < 6.0          # the vehicle file's, not the default


def test_limits_are_the_flags_else_the_lower_of_mission_and_vehicle(tmp_path):
    m = tmp_path / "m.toml"
    m.write_text('duration = 5\n[trajectory]\nkind = "circle"\nradius = 5.0\nspeed = 1.0\n'
                 "[limits]\nmax_speed = 2.0\nmax_yaw_rate = 1.0\n")
    mission = missions.load(m)
    paper = missions.paper_ellipse()
    vehicle = KnownVehicle(limits=Limits(3.0, 0.5))
    assert choose_limits(paper, GainOptions()) == DEFAULT_LIMITS
    assert choose_limits(paper, GainOptions(), vehicle) == Limits(3.0, 0.5)
    assert choose_limits(mission, GainOptions(), vehicle) == Limits(2.0, 0.5)
    assert choose_limits(mission, GainOptions(max_speed=4.0), vehicle) == Limits(4.0, 0.5)
    assert choose_limits(None, GainOptions()) == DEFAULT_LIMITS


def test_the_vehicles_gains_come_after_the_missions_and_before_the_shipped(tmp_path):
    own = TunedGains(FilterGains(111.0, 11.0), PZCGains(0.3, 0.4), rate_hz=40.0, w_c=2.0,
                     source="beside")
    paper = missions.paper_ellipse()
    r = resolve(paper, GainOptions(), KnownVehicle(gains=own))
    assert r.rate == 40.0 and r.gains.filter.k_df == 111.0 and r.gains.source == "vehicle beside"
    m = tmp_path / "m.toml"
    m.write_text('duration = 5\n[trajectory]\nkind = "ellipse"\nf_r = 0.1\n'
                 "[gains.filter]\nk_df = 500.0\nlambda_f = 50.0\n")
    r = resolve(missions.load(m), GainOptions(), KnownVehicle(gains=own))
    assert r.gains.filter.k_df == 500.0 and r.gains.pzc.k_dc == 0.3   # each part on its own
