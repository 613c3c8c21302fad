"""A field's GNSS on the real autopilot (issue 44): ArduPilot Rover SITL (``rover-skid``, the
bundled vehicle file) takes its fixes from the seeded injector (``GPS1_TYPE 14``, GPS_INPUT on
SERIAL2, :mod:`testbed.gnss_input`), and each flight is scored from the simulator's truth
(``SIM_STATE``, :mod:`testbed.gnss_flight`): RTK fixed tracks to centimetres; 8 s of RTK float
hold the rover on the path and the mission completes with nothing skipped; a 0.25 m multipath
jump while "fixed" is ridden through, not followed. Real time (the injector paces on the wall
clock). Each test prints its figures. Skipped unless ARDUPILOT_SITL or ARDUPILOT_DIR is set.
"""

from __future__ import annotations

import math

import pytest

from testbed.ardupilot import CompanionProcess
from testbed.gnss import SCENARIOS, Drift, Scenario, Window
from testbed.gnss_flight import Truth, companion_trace, gnss_vehicle, score
from testbed.gnss_input import sitl_params
from testbed.missions import ellipse_mission
from testbed.process import ROOT

pytestmark = [pytest.mark.sitl, pytest.mark.slow]

VEHICLE = ROOT / "companion" / "sim" / "vehicles" / "ardupilot_skid.toml"
DURATION, STEADY = 40.0, 15.0           # mission s; the steady RMS's last seconds
RTK = SCENARIOS["rtk-fixed"]
FLOAT = Scenario("rtk-float", white=0.008, drift=Drift(0.01, 30.0),
                 windows=(Window(18.0, 8.0, drift=Drift(0.4, 8.0), h_acc=0.4),))
JUMP = Scenario("multipath", white=0.008, drift=Drift(0.01, 30.0),
                windows=(Window(18.0, 4.0, jump=(0.25 * math.cos(2.2), 0.25 * math.sin(2.2))),))


def _fly(ardupilot, tmp_path, scenario: Scenario) -> tuple[dict, dict, str]:
    sitl = ardupilot(speedup=1, params=sitl_params(scenario))
    mission = ellipse_mission(tmp_path / "ellipse.toml", DURATION, f_r=0.04)
    logs = tmp_path / "logs"
    with gnss_vehicle(sitl, scenario, seed=1, logs=logs) as inj:
        began = inj.begin()
        with CompanionProcess(sitl.url(0), "--vehicle", str(VEHICLE), "--mission", str(mission),
                              "--arm", "--json", "--no-zenoh", "--log-dir", str(logs)) as comp:
            code = comp.wait(DURATION + 120.0)
            r = comp.result()
        assert code == 0 and r["reason"] == "mission_done", comp.stderr[-3000:]
        figures = score(companion_trace(r), Truth(list(inj.truth), list(inj.clock)), scenario,
                        DURATION, began, steady_s=STEADY)
    print(f"\n{scenario.name}: truth {figures['truth']:.3f} m, floor {figures['floor']:.3f} m, "
          f"faults {figures['faults']}, gnss {r['gnss']['drop_log']}, "
          f"jumps ridden {r['gnss']['jumps_ridden']}")
    return r, figures, comp.stderr


def test_rtk_fixed_tracks_the_truth_to_centimetres(ardupilot, tmp_path):
    r, f, _ = _fly(ardupilot, tmp_path, RTK)
    assert r["gnss"]["run_fix"] == "RTK fixed" and not r["gnss"]["drop_log"], r["gnss"]
    assert f["truth"] <= f["floor"] + 0.02 and f["truth"] <= 0.06, f


def test_rtk_float_holds_on_the_path_and_the_mission_completes(ardupilot, tmp_path):
    r, f, stderr = _fly(ardupilot, tmp_path, FLOAT)
    drops = r["gnss"]["drop_log"]
    assert [d["action"] for d in drops] == ["hold"] and drops[0]["fix"] == "RTK float", drops
    assert "GNSS back to the run's RTK fixed" in stderr
    assert r["duration_s"] >= DURATION - 1e-6                  # nothing of the path skipped
    (window,) = f["faults"]
    assert window["from_path"] <= 0.1, f                       # held on the path in truth


def test_a_multipath_jump_is_ridden_through_not_followed(ardupilot, tmp_path):
    r, f, stderr = _fly(ardupilot, tmp_path, JUMP)
    assert "riding through on the receiver less the jump" in stderr
    assert r["gnss"]["jumps_ridden"] >= 1 and r["failsafes"] == 0, r["gnss"]
    (window,) = f["faults"]
    assert window["from_path"] <= 0.08, f
