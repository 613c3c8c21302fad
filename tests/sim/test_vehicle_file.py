"""Vehicle files: read back to the same model, the paper's plant as the empty file, one-line errors."""

from __future__ import annotations

import math

import pytest

from companion.errors import UserError
from companion.sim import vehicle_file
from companion.sim.plant import RoverParams

FULL = RoverParams(d_cen=0.1, w_c=1 / 0.3, w_c_yaw=1 / 0.05, max_speed=4.0, max_yaw_rate=2.0944,
                   max_accel=1.0, max_decel=1.5, max_yaw_accel=2.09, max_yaw_decel=2.5,
                   speed_delay=0.06, yaw_delay=0.04, turn_speed_coupling=0.3,
                   speed_turn_coupling=0.15)


def test_round_trip_keeps_every_parameter(tmp_path):
    path = tmp_path / "v.toml"
    vehicle_file.save(vehicle_file.VehicleFile(FULL, name="skid", header="made by a test\nline 2",
                                               fit={"speed_rms_m_s": 0.05}), path)
    text = path.read_text()
    assert text.startswith("# made by a test\n# line 2\n")
    assert "\n[coupling]\nturn_speed = 0.3\nspeed_turn = 0.15\n" in text
    back = vehicle_file.load(path)
    assert back.name == "skid" and back.fit == {"speed_rms_m_s": 0.05}
    for name in ("d_cen", "w_c", "w_c_yaw", "max_speed", "max_yaw_rate", "max_accel", "decel",
                 "max_yaw_accel", "yaw_decel", "speed_delay", "yaw_delay", "turn_speed_coupling",
                 "speed_turn_coupling"):
        assert getattr(back.params, name) == pytest.approx(getattr(FULL, name), rel=1e-5), name


def test_the_empty_file_is_the_papers_plant(tmp_path):
    path = tmp_path / "paper.toml"
    path.write_text('schema = "pzc-rover/vehicle/1"\n')
    params = vehicle_file.load(path).params
    assert params.is_paper and params.w_c == pytest.approx(20.0)
    assert math.isinf(params.max_speed)
    unlimited = vehicle_file.VehicleFile(RoverParams.paper())
    path.write_text(vehicle_file.dumps(unlimited))
    assert 'max_m_s = "inf"' in path.read_text() and vehicle_file.load(path).params.is_paper


@pytest.mark.parametrize("body, message", [
    ('schema = "other"', "schema: must be"),
    ('schema = "pzc-rover/vehicle/1"\nspeed = 3', "'speed' must be a table"),
    ('schema = "pzc-rover/vehicle/1"\n[speed]\nlag_s = -1', "speed.lag_s: must be >= 0"),
    ('schema = "pzc-rover/vehicle/1"\n[speed]\nmax_m_s = 0', "speed.max_m_s: must be > 0"),
    ('schema = "pzc-rover/vehicle/1"\n[turn_rate]\ndelay_s = 9', "turn_rate.delay_s: must be between"),
    ('schema = "pzc-rover/vehicle/1"\n[coupling]\nturn_speed = 1.5', "coupling.turn_speed"),
    ('schema = "pzc-rover/vehicle/1"\n[coupling]\nspeed_turn = -0.1', "coupling.speed_turn"),
    ('schema = "pzc-rover/vehicle/1"\n[speed]\nmax_speed = 3', "unknown key 'speed.max_speed'"),
    ('schema = "pzc-rover/vehicle/1"\nwheels = 4', "unknown key 'wheels'"),
    ('schema = "pzc-rover/vehicle/1"\n[speed]\nlag_s = "fast"', "speed.lag_s: must be a finite"),
    ("schema = [", "not valid TOML"),
])
def test_bad_files_are_one_line_errors_naming_the_key(tmp_path, body, message):
    path = tmp_path / "bad.toml"
    path.write_text(body)
    with pytest.raises(UserError) as err:
        vehicle_file.load(path)
    assert message in str(err.value) and str(path) in str(err.value)
    assert "\n" not in str(err.value)


def test_missing_file(tmp_path):
    with pytest.raises(UserError, match="no such vehicle file"):
        vehicle_file.load(tmp_path / "nope.toml")


MISSION = """name = "m"
duration = 20
[trajectory]
kind = "circle"
radius = 5.0
speed = 1.0
[vehicle]
{vehicle}
"""


def test_a_mission_names_its_vehicle_file(tmp_path):
    from companion import mission
    vehicle_file.save(vehicle_file.VehicleFile(FULL, name="skid"), tmp_path / "rover.toml")
    path = tmp_path / "m.toml"
    path.write_text(MISSION.format(vehicle='file = "rover.toml"\nd_cen = 0.25'))
    m = mission.load(path)
    assert m.vehicle_file == str(tmp_path / "rover.toml")
    assert m.vehicle is None            # named, not read: the command loads it once
    from companion.app.vehicle import for_flight
    m, loaded = for_flight(None, m)
    assert loaded is not None and loaded.path == m.vehicle_file
    assert m.vehicle.max_accel == pytest.approx(1.0) and m.vehicle.speed_delay == pytest.approx(0.06)
    assert m.vehicle.d_cen == pytest.approx(0.25)            # the mission's key wins
    path.write_text(MISSION.format(vehicle='file = "missing.toml"'))
    with pytest.raises(UserError) as err:
        mission.load(path)
    assert "vehicle.file" in str(err.value) and "no such vehicle file" in str(err.value)
    # a file there but broken: one line naming the mission, the key and the file's own problem
    (tmp_path / "broken.toml").write_text('schema = "pzc-rover/vehicle/1"\n[speed]\nlag_s = -1\n')
    path.write_text(MISSION.format(vehicle='file = "broken.toml"'))
    with pytest.raises(UserError) as err:
        for_flight(None, mission.load(path))
    assert str(err.value).startswith(f"{path}: [vehicle] file: ") and "lag_s" in str(err.value)
    assert "\n" not in str(err.value)
