"""A field on the real autopilot (issue 45): ArduPilot Rover SITL (``rover-skid``, the bundled
vehicle file) with exact injected fixes (scenario ``none``: the truth known, the estimate good)
flies missions/field.toml's field placed where it boots; scored from the simulator's truth
(:mod:`companion.mission.coverage`): the swaths driven within centimetres, the boundary never crossed,
nothing of the swath area missed. Real time, about 3 minutes. Prints its figures. Skipped
unless ARDUPILOT_SITL or ARDUPILOT_DIR is set; a candidate until ten runs in a row beside
another SITL.
"""

from __future__ import annotations

import time

import pytest

from companion import mission as missions
from companion.mission.coverage import figures
from testbed.ardupilot import CompanionProcess
from testbed.gnss import SCENARIOS
from testbed.gnss_flight import gnss_vehicle, truth_between
from testbed.gnss_input import sitl_params
from testbed.marks import CANDIDATE
from testbed.missions import FIELD_SPACING, field_mission
from testbed.process import ROOT

pytestmark = [pytest.mark.sitl, pytest.mark.slow]

VEHICLE = ROOT / "companion" / "sim" / "vehicles" / "ardupilot_skid.toml"


@CANDIDATE
def test_a_field_is_driven_on_its_swaths_inside_its_boundary(ardupilot, tmp_path):
    scenario = SCENARIOS["none"]
    sitl = ardupilot(speedup=1, params=sitl_params(scenario))
    mission = field_mission(tmp_path / "field.toml", turn_rate=0.5)
    m = missions.load(mission)
    logs = tmp_path / "logs"
    with gnss_vehicle(sitl, scenario, seed=1, logs=logs) as inj:
        t0 = time.time()
        with CompanionProcess(sitl.url(0), "--vehicle", str(VEHICLE), "--mission", str(mission),
                              "--arm", "--json", "--no-zenoh", "--log-dir", str(logs)) as comp:
            code = comp.wait(m.duration + 120.0)
            r = comp.result()
        t1 = time.time()
        assert code == 0 and r["reason"] == "mission_done", comp.stderr[-3000:]
        f = figures(truth_between(inj, t0, t1), m.trajectory.cover, FIELD_SPACING + 0.1)
    print(f"\nfield on SITL, from the truth: cross-track p50 {f['cross_track_p50']:.3f} p95 "
          f"{f['cross_track_p95']:.3f} max {f['cross_track_max']:.3f} m, excursion "
          f"{f['excursion']:.3f} m, missed {100 * f['missed']:.2f} %, lean out / back "
          f"{f['lean_out_back']}; the run's own (its estimate): {r['coverage']}")
    assert f["on_swaths"] > 0.4 * f["samples"]
    # measured 0.037-0.041 / 0.047-0.073 (docs/benchmarks.md); ArduPilot's AUTO 0.22 / 0.30
    assert f["cross_track_p95"] <= 0.06 and f["cross_track_max"] <= 0.1, f
    assert f["excursion"] == 0.0 and f["missed"] <= 0.005, f
