"""A vehicle loaded once (companion/vehicle.py, companion/app/vehicle.py): the record a command
builds where it starts, with its autopilot and steering kind, limits, gains and tuner settings;
and nothing below the commands opening a vehicle file."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from companion import profiles
from companion.app import vehicle as loader
from companion.core.filter import FilterGains
from companion.core.pzc import PZCGains
from companion.errors import UserError
from companion.sim import vehicle_file
from companion.sim.gains import TunedGains
from companion.sim.plant import RoverParams
from companion.vehicle import from_bytes

ROOT = Path(__file__).resolve().parents[2]
CAR = RoverParams(max_speed=2.0, max_yaw_rate=1.5, min_turn_radius=0.9)


def _write(path: Path, params: RoverParams, **names: str) -> Path:
    vehicle_file.save(vehicle_file.VehicleFile(params, name="v", **names), path)
    return path


def test_a_file_names_its_autopilot_and_steering_kind_and_reads_back(tmp_path):
    path = _write(tmp_path / "car.toml", CAR, autopilot="ardupilot", steering="ackermann")
    assert 'autopilot = "ardupilot"' in path.read_text()
    v = loader.load(path)
    assert v.autopilot is profiles.AUTOPILOTS["ardupilot"]
    assert v.steering is profiles.STEERING["ackermann"] and v.kinds_named
    assert v.limits.min_turn_radius == pytest.approx(0.9)        # a car on turn-rate setpoints
    assert v.tune_settings == profiles.tune_settings(v.autopilot, v.steering)
    assert v.text == path.read_text()


def test_a_file_without_the_names_has_them_inferred_and_says_so(tmp_path):
    v = loader.load(_write(tmp_path / "old.toml", CAR))
    assert not v.kinds_named
    assert (v.autopilot, v.steering) == profiles.kinds_of_model(CAR)


@pytest.mark.parametrize("key, value", [("autopilot", "betaflight"), ("steering", "tank")])
def test_an_unknown_profile_name_is_one_line_naming_the_file_and_key(tmp_path, key, value):
    path = _write(tmp_path / "v.toml", CAR, **{key: value})
    with pytest.raises(UserError) as err:
        loader.load(path)
    assert str(err.value).startswith(f"{path}: {key}: {value!r} is not one of")


def test_only_gains_tuned_for_these_very_bytes_are_kept(tmp_path):
    path = _write(tmp_path / "vehicle.toml", CAR)
    sha = loader.load(path).sha256
    own = (FilterGains(), PZCGains())
    TunedGains(*own, rate_hz=40.0, w_c=20.0, vehicle_file="vehicle.toml",
               vehicle_sha256=sha).save(tmp_path / "gains.toml")
    TunedGains(*own, rate_hz=20.0, w_c=20.0, vehicle_file="vehicle.toml",
               vehicle_sha256="0" * 64).save(tmp_path / "old.toml")
    v = loader.load(path)
    assert v.gains_at(40.0) is not None and v.gains_at(20.0) is None
    assert from_bytes(path.read_bytes() + b"\n", str(path), v.gains_beside).gains_at(40.0) is None


def test_the_bundled_vehicle_names_its_kinds_and_keeps_its_gains():
    v = loader.bundled("ardupilot-skid")
    assert v is not None and v.kinds_named and v.steering.name == "skid"
    assert v.gains_at(40.0) is not None, "re-record the preset's gains: its vehicle file changed"


def _calls_to_load(path: Path) -> list[int]:
    tree = ast.parse(path.read_text())
    return [n.lineno for n in ast.walk(tree) if isinstance(n, ast.Call)
            and isinstance(n.func, ast.Attribute) and n.func.attr == "load"
            and isinstance(n.func.value, ast.Name) and n.func.value.id in ("vehicle_file",
                                                                           "_vehicle_file")]


def test_nothing_below_the_commands_opens_a_vehicle_file():
    below = [p for p in sorted((ROOT / "companion").rglob("*.py"))
             if p.relative_to(ROOT / "companion").parts[0] not in ("commands", "app")]
    found = [f"{p.relative_to(ROOT)}:{line}" for p in below for line in _calls_to_load(p)
             if p.name != "vehicle_file.py"]     # its own preset() reads the bundled files
    assert not found, found


def test_a_command_parses_its_vehicle_file_once(monkeypatch, capsys):
    # companion simulate --vehicle, in process: the file named by the flag, the gains beside it,
    # the limits and the tuner's settings all come from one parse (it was three before)
    from companion.cli import main
    parsed: list[str] = []
    real = vehicle_file.parse
    monkeypatch.setattr(vehicle_file, "parse",
                        lambda data, where: parsed.append(where) or real(data, where))
    bundled = ROOT / "companion" / "sim" / "vehicles" / "ardupilot_skid.toml"
    code = main(["simulate", "--vehicle", str(bundled), "--mission",
                 str(ROOT / "missions" / "paper_ellipse_004.toml"), "--json"])
    assert code == 0, capsys.readouterr().err
    assert parsed == [str(bundled)]
