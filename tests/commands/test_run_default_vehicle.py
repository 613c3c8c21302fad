"""``companion run`` without a vehicle file or gains: the bundled vehicle the live one matches
(by the parameters the preset was identified with, read over MAVLink), else a warning naming
``companion calibrate`` (companion/live/presets.py), against ``sitl-plant`` over real UDP."""

from __future__ import annotations

import pytest

from companion import profiles
from companion.app.vehicle import bundled
from companion.live import presets
from companion.sim import vehicle_file
from sitl_plant.testing import PlantProcess
from testbed.missions import ellipse_mission
from testbed.process import Companion

ARDUPILOT = profiles.autopilot_named("ardupilot")
RECORDED = presets.recorded(ARDUPILOT, bundled("ardupilot-skid"))
SKID_SERVOS = {"SERVO1_FUNCTION": 73.0, "SERVO3_FUNCTION": 74.0}
CAR_SERVOS = {"SERVO1_FUNCTION": 26.0, "SERVO3_FUNCTION": 70.0}


def test_the_preset_records_the_parameters_it_was_identified_with():
    # stock rover-skid's inner-loop limits and speeds, as the identification read them
    assert RECORDED["ATC_ACCEL_MAX"] == 1.0 and RECORDED["ATC_STR_RAT_MAX"] == 120.0
    assert set(RECORDED) <= set(ARDUPILOT.ident.params) and len(RECORDED) >= 8


def test_a_vehicle_with_the_recorded_parameters_and_steering_matches():
    table = {"ardupilot-skid": RECORDED}
    assert presets.match(ARDUPILOT, {**RECORDED, **SKID_SERVOS}, table) == ("ardupilot-skid", "")
    # float32 on the wire: 1.0000001 is still 1
    near = {**RECORDED, "ATC_ACCEL_MAX": 1.0000001, **SKID_SERVOS}
    assert presets.match(ARDUPILOT, near, table)[0] == "ardupilot-skid"


@pytest.mark.parametrize("values, says", [
    ({**RECORDED, "ATC_STR_RAT_MAX": 90.0, **SKID_SERVOS}, "ATC_STR_RAT_MAX 120, this vehicle has 90"),
    ({k: v for k, v in RECORDED.items() if k != "WP_SPEED"} | SKID_SERVOS,
     "WP_SPEED 3, this vehicle does not report it"),
    ({**RECORDED, **CAR_SERVOS}, "this one's frame shows Ackermann"),
    (dict(RECORDED), "no known steering kind"),
])
def test_another_setting_or_steering_kind_does_not_match_and_says_why(values, says):
    name, why = presets.match(ARDUPILOT, values, {"ardupilot-skid": RECORDED})
    assert name is None and says in why


def test_px4_has_no_bundled_vehicle():
    px4 = profiles.autopilot_named("px4")
    assert presets.match(px4, {}, {}) == (None, "no bundled vehicle for this autopilot")


def _fly(tmp_path, plant_args, *args):
    mission = ellipse_mission(tmp_path / "m.toml", 8.0, f_r=0.04)
    with PlantProcess("--lockstep", "--tick-aligned", *plant_args) as plant, \
            Companion(plant.port, "--mission", str(mission), "--arm", "--json", "--no-zenoh",
                      "--no-log", *args) as comp:
        assert comp.wait(90) == 0, comp.stderr
    return comp.result(), comp.stderr


def test_run_on_the_presets_vehicle_flies_its_gains_and_limits(tmp_path):
    # the plant serves the parameters stock rover-skid has (and its skid-steer servos)
    served = [a for k, v in RECORDED.items() for a in ("--param", f"{k}={v:g}")]
    r, stderr = _fly(tmp_path, ["--preset", "ardupilot-skid", *served])
    vpath = vehicle_file.preset_path("ardupilot-skid")
    assert r["vehicle_preset"] == "ardupilot-skid" and "vehicle_warning" not in r
    assert r["gains_source"] == f"vehicle {vpath.with_name('ardupilot_skid.gains-40hz.toml')}"
    params = vehicle_file.load(vpath).params
    assert r["limits"] == {"max_speed": pytest.approx(params.max_speed),
                           "max_yaw_rate": pytest.approx(params.max_yaw_rate)}
    assert "matches the bundled ardupilot-skid" in stderr


def test_run_on_another_vehicle_warns_and_names_calibrate(tmp_path):
    r, stderr = _fly(tmp_path, ["--param", "ATC_STR_RAT_MAX=90"])
    assert "vehicle_preset" not in r
    assert "not tuned for this vehicle" in r["vehicle_warning"]
    assert "companion calibrate --connect udpin:127.0.0.1:" in r["vehicle_warning"]
    assert "WARNING: the gains are not tuned for this vehicle" in stderr
    assert r["limits"] == {"max_speed": 6.0, "max_yaw_rate": 6.0}      # nothing known of it


def test_gains_given_are_flown_without_looking_for_a_preset(tmp_path):
    gains = tmp_path / "g.toml"
    from companion.core.filter import FilterGains
    from companion.core.pzc import PZCGains
    from companion.sim.gains import TunedGains
    TunedGains(FilterGains(), PZCGains(), rate_hz=40.0, w_c=20.0).save(gains)
    r, stderr = _fly(tmp_path, [], "--gains", str(gains))
    assert "vehicle_warning" not in r and "vehicle_preset" not in r
    assert "bundled" not in stderr and "WARNING" not in stderr
