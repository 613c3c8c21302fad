"""The bundled plant with a vehicle model: ArduPilot's telemetry ticks, and `sitl-plant --vehicle`
flying the delays, rate limits and coupling of a vehicle file, checked over real UDP."""

from __future__ import annotations

import numpy as np
import pytest

from companion.sim import vehicle_file
from companion.sim.plant import RoverParams
from sitl_plant import streams
from sitl_plant.testing import Pilot, PlantProcess


def _intervals_ms(schedule: streams.StreamSchedule, msg_id: int, until_us: int) -> list[float]:
    sent, now = [], 0
    while now < until_us:
        now = schedule.next_due_us()
        if msg_id in schedule.due(now):
            sent.append(now)
    return list(np.diff(sent) / 1000.0)


def test_tick_aligned_40_hz_on_a_50_hz_scheduler_arrives_at_20_20_20_40_ms():
    aligned = streams.StreamSchedule(50.0, tick_aligned=True)
    assert aligned.request(streams.LOCAL_POSITION_NED, 25_000, 0).result == streams.ACCEPTED
    gaps = _intervals_ms(aligned, streams.LOCAL_POSITION_NED, 2_000_000)
    assert sorted(set(gaps)) == [20.0, 40.0]
    assert np.mean(gaps) == pytest.approx(25.0, abs=0.5)            # still 40 Hz on average
    assert gaps[4:8] in ([20.0, 20.0, 20.0, 40.0], [20.0, 20.0, 40.0, 20.0],
                         [20.0, 40.0, 20.0, 20.0], [40.0, 20.0, 20.0, 20.0])
    plain = streams.StreamSchedule(50.0)
    plain.request(streams.LOCAL_POSITION_NED, 25_000, 0)
    assert set(_intervals_ms(plain, streams.LOCAL_POSITION_NED, 1_000_000)) == {25.0}


def test_sitl_plant_flies_a_vehicle_files_rate_limit_and_delay(tmp_path):
    # A vehicle that ramps its speed at 0.5 m/s^2 (behind a 0.2 s delay): 1 s after it starts
    # moving it does 0.5 m/s, not the 2 m/s asked; telemetry comes on the 50 Hz ticks.
    path = tmp_path / "slow.toml"
    vehicle_file.save(vehicle_file.VehicleFile(RoverParams(
        w_c=50.0, max_speed=4.0, max_accel=0.5, speed_delay=0.2, max_yaw_rate=2.0)), path)
    with PlantProcess("--vehicle", str(path), "--tick-aligned") as plant, Pilot(plant.port) as pilot:
        pilot.wait("HEARTBEAT")
        assert pilot.set_rate(32, 40.0) == 0
        assert pilot.set_mode(15) == 0 and pilot.arm() == 0
        samples = pilot.stream(lambda: pilot.speed_turn_rate(2.0, 0.0), 2.0, hz=20.0)
    t = np.array([m.time_boot_ms for m in samples]) / 1000.0
    v = np.array([m.vx for m in samples])                   # heading north: vx is the speed
    moving = t[v > 1e-3][0]
    later = np.interp(moving + 1.0, t, v)
    assert later == pytest.approx(0.5, abs=0.08)          # 1 s of ramp at 0.5 m/s^2
    assert np.max(np.diff(v) / np.maximum(np.diff(t), 1e-3)) < 0.5 * 1.1
    assert set(np.round(np.diff(t) * 1000).astype(int)) <= {20, 40}


def test_unknown_or_bad_vehicle_file_is_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('schema = "pzc-rover/vehicle/1"\n[speed]\nlag_s = -2\n')
    for argv, message in ((["--vehicle", str(bad)], "speed.lag_s: must be >= 0"),
                          (["--vehicle", str(tmp_path / "none.toml")], "no such vehicle file")):
        plant = PlantProcess(*argv, "--duration", "1")
        with plant:
            code = plant.proc.wait(10)
            err = plant.proc.stderr.read()
        assert code == 2 and message in err and "Traceback" not in err
        assert len(err.strip().splitlines()) == 1


def test_demo_and_the_plant_offer_the_same_vehicle_presets():
    from companion.cli import build_parser
    from sitl_plant.cli import build_parser as plant_parser

    def choices(parser, flag):
        return next(a.choices for a in parser._actions if flag in a.option_strings)

    demo = next(a for a in build_parser()._actions if hasattr(a, "choices") and
                isinstance(a.choices, dict) and "demo" in a.choices).choices["demo"]
    assert tuple(choices(demo, "--preset")) == vehicle_file.PRESETS
    assert tuple(choices(plant_parser(), "--preset")) == vehicle_file.PRESETS
