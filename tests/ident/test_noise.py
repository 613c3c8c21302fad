"""The pose estimate's noise at a stand still (companion.ident.noise): measured from the samples
where the rover stood, white noise through second differences (a slow drift cancels), and
written into the vehicle file for the tuner (companion.vehicle.Vehicle.tune_settings)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from companion.app import vehicle as loader
from companion.errors import UserError
from companion.ident.noise import measure, of_flight, still_mask
from companion.sim import vehicle_file
from companion.sim.plant import RoverParams
from companion.sim.robust.config import RobustConfig

RATE = 40.0


def _flight(sigma: float, still_s: float, drift: float = 0.0, seed: int = 1):
    """``still_s`` s at rest, then 10 s driving at 1 m/s, then 4 s at rest; the estimate
    carries white noise ``sigma`` and a slow drift (m/s) throughout."""
    rng = np.random.default_rng(seed)
    n_still, n_move, n_end = int(still_s * RATE), int(10 * RATE), int(4 * RATE)
    n = n_still + n_move + n_end
    t = np.arange(n) / RATE
    speed = np.concatenate([np.zeros(n_still), np.ones(n_move), np.zeros(n_end)])
    x = np.cumsum(speed) / RATE + drift * t + rng.normal(0, sigma, n)
    y = drift * t + rng.normal(0, sigma, n)
    yaw = rng.normal(0, sigma / 4, n)
    cmd_t = t[::2]
    speed_cmd = np.where((cmd_t >= t[n_still]) & (cmd_t < t[n_still + n_move]), 1.0, 0.0)
    return SimpleNamespace(t=t, x=x, y=y, yaw=yaw, speed=speed, yaw_rate=np.zeros(n),
                           cmd_t=cmd_t, speed_cmd=speed_cmd, yaw_rate_cmd=np.zeros_like(cmd_t))


@pytest.mark.parametrize("sigma", [0.002, 0.01, 0.05])
def test_white_noise_at_a_stand_still_is_measured_and_a_drift_is_not(sigma):
    noise = of_flight(_flight(sigma, still_s=5.0, drift=0.05))
    assert noise is not None
    assert noise.position_m == pytest.approx(sigma, rel=0.12)
    assert noise.yaw_rad == pytest.approx(sigma / 4, rel=0.12)
    # the start's 5 s and the end's 4 s less the 2 s settling after the last moving setpoint
    assert noise.seconds == pytest.approx(5.0 + 2.0, abs=0.2)


def test_samples_while_moving_or_just_after_do_not_count():
    f = _flight(0.01, still_s=5.0)
    still = still_mask(f.t, f.speed, f.yaw_rate, f.cmd_t, f.speed_cmd != 0)
    moving = (f.t >= 5.0) & (f.t < 15.0 + 2.0 - 0.05)
    assert not still[moving].any() and still[f.t < 5.0].all() and still[f.t > 17.1].all()


def test_too_short_a_stand_still_says_nothing():
    f = _flight(0.01, still_s=0.4)
    f.t, f.x, f.y, f.yaw = f.t[:400], f.x[:400], f.y[:400], f.yaw[:400]
    f.speed, f.yaw_rate = f.speed[:400], f.yaw_rate[:400]
    assert measure(f.t, f.x, f.y, f.yaw, np.zeros(400, dtype=bool)) is None
    assert of_flight(f) is None


def _vehicle(tmp_path, **estimate):
    path = tmp_path / "v.toml"
    vehicle_file.save(vehicle_file.VehicleFile(RoverParams(max_speed=2.0), name="v",
                                               autopilot="ardupilot", steering="skid",
                                               estimate=estimate), path)
    return path


def test_the_noise_goes_into_the_vehicle_file_and_the_tuner_tunes_for_more_than_its_default(
        tmp_path):
    loud = loader.load(_vehicle(tmp_path, position_noise_m=0.03, yaw_noise_rad=0.001,
                                still_s=12.0))
    assert "[estimate]" in loud.text and loud.file.estimate["position_noise_m"] == 0.03
    assert loud.tune_settings["noise_pos"] == 0.03
    assert "noise_yaw" not in loud.tune_settings        # under the tuner's own default
    quiet = loader.load(_vehicle(tmp_path, position_noise_m=0.001))
    assert "noise_pos" not in quiet.tune_settings
    assert RobustConfig.noise_pos > 0.001


@pytest.mark.parametrize("table, says", [
    ("position_noise_m = -1", "estimate.position_noise_m: must be >= 0"),
    ("position_noise_m = 3.0", "estimate.position_noise_m: must be at most 1"),
    ("hdop = 1.0", "unknown key 'estimate.hdop'"),
])
def test_a_bad_estimate_table_is_one_line_naming_the_key(tmp_path, table, says):
    path = _vehicle(tmp_path)
    path.write_text(path.read_text() + f"\n[estimate]\n{table}\n")
    with pytest.raises(UserError, match=says.replace(".", r"\.").replace("(", r"\(")):
        loader.load(path)
