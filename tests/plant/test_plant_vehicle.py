"""Unit tests of the plant's pure parts: the autopilot state machine, setpoint decoding, message
intervals, telemetry impairments and the lockstep gate. No processes, no sockets."""

from __future__ import annotations

import math

import pytest

from companion.profiles import ardupilot
from companion.profiles import px4 as px4_profile
from companion.profiles import setpoint as sp
from companion.sim.plant import RoverParams
from sitl_plant import modes
from sitl_plant.clock import LockstepGate, Pacer
from sitl_plant.streams import ATTITUDE, LOCAL_POSITION_NED, StreamSchedule
from sitl_plant.telemetry import TelemetryConfig, TelemetryPipe
from sitl_plant.vehicle import GUIDED_TIMEOUT_TEXT, OFFBOARD_LOST_TEXT, Result, Vehicle, VehicleConfig

DT = 0.001
AP_GUIDED, AP_HOLD = ardupilot.PROFILE.mode_number("GUIDED"), ardupilot.PROFILE.mode_number("HOLD")
PX4_OFFBOARD = px4_profile.PROFILE.mode_number("OFFBOARD")
PX4_HOLD = px4_profile.PROFILE.mode_number("LOITER")        # PX4's Hold, AUTO_LOITER


def run(v: Vehicle, seconds: float) -> None:
    for _ in range(int(round(seconds / DT))):
        v.step(DT)


def guided_armed(**kw) -> Vehicle:
    v = Vehicle(VehicleConfig(**kw))
    assert v.set_mode(AP_GUIDED) is Result.ACCEPTED
    assert v.arm(True) is Result.ACCEPTED
    v.pop_texts()
    return v


def rate_setpoint(speed: float, rate: float) -> sp.Setpoint:
    return sp.Setpoint(sp.FRAME_BODY_NED, 1511, vx=speed, yaw_rate=rate)


# --- ArduPilot state machine ----------------------------------------------------------------
def test_modes_and_base_mode_flags():
    v = Vehicle()
    assert v.custom_mode == 0 and v.base_mode & modes.FLAG_CUSTOM_MODE_ENABLED
    assert v.set_mode(AP_GUIDED) is Result.ACCEPTED
    assert v.base_mode & modes.FLAG_GUIDED_ENABLED and not v.base_mode & modes.FLAG_SAFETY_ARMED
    v.arm(True)
    assert v.base_mode & modes.FLAG_SAFETY_ARMED
    assert v.set_mode(2) is Result.FAILED and v.custom_mode == AP_GUIDED  # no mode 2
    assert v.set_mode(16) is Result.FAILED                                   # INITIALISING
    assert v.set_mode(None) is Result.FAILED
    assert "Mode changed to GUIDED" in [t for _, t in v.pop_texts()]


def test_arm_delay_refuses_then_accepts():
    v = Vehicle(VehicleConfig(arm_delay=2.0))
    assert v.arm(True) is Result.TEMPORARILY_REJECTED and not v.armed
    assert "Arm: AHRS: not using configured AHRS type" in [t for _, t in v.pop_texts()]
    run(v, 2.0)
    assert v.arm(True) is Result.ACCEPTED and v.armed


def test_setpoints_ignored_unless_guided_and_armed():
    v = Vehicle()
    v.arm(True)
    assert v.setpoint(rate_setpoint(1.0, 0.0)) == "not guided and armed"      # MANUAL, armed
    v.arm(False)
    v.set_mode(AP_GUIDED)
    assert v.setpoint(rate_setpoint(1.0, 0.0)) == "not guided and armed"      # GUIDED, disarmed
    run(v, 0.5)
    assert v.state.x == 0.0 and v.state.v == 0.0
    v.arm(True)
    assert v.setpoint(rate_setpoint(1.0, 0.0)) == "used"
    run(v, 0.5)
    assert v.state.x > 0.3


def test_speed_turn_rate_setpoint_reaches_commanded_values():
    v = guided_armed()
    v.setpoint(rate_setpoint(1.5, 0.3))
    run(v, 1.0)   # paper plant: w_c = 20 rad/s, settled in well under a second
    assert v.state.v == pytest.approx(1.5, rel=1e-3)
    assert v.state.omega == pytest.approx(0.3, rel=1e-3)
    assert math.hypot(*v.velocity()) == pytest.approx(1.5, rel=1e-3)


def test_guided_timeout_after_exactly_three_seconds():
    v = guided_armed()
    v.setpoint(rate_setpoint(1.0, 0.0))
    run(v, 2.999)
    assert v.commands() == (1.0, 0.0) and not v.pop_texts()
    run(v, 0.002)
    assert v.commands() == (0.0, 0.0)
    assert [t for _, t in v.pop_texts()] == [GUIDED_TIMEOUT_TEXT]
    assert v.custom_mode == AP_GUIDED          # stays in GUIDED
    run(v, 5.0)
    assert not v.pop_texts()                          # said once


def test_position_targets_never_time_out_and_stop_within_half_a_metre():
    v = guided_armed()
    v.setpoint(sp.Setpoint(sp.FRAME_LOCAL_NED, 3580, x=4.0, y=3.0))
    run(v, 30.0)
    assert GUIDED_TIMEOUT_TEXT not in [t for _, t in v.pop_texts()]
    assert math.hypot(4.0 - v.state.x, 3.0 - v.state.y) < 0.5
    assert abs(v.state.v) < 1e-3


def test_entering_guided_starts_stopped_and_hold_stops():
    v = guided_armed()
    v.setpoint(rate_setpoint(1.0, 0.0))
    run(v, 0.5)
    v.set_mode(AP_HOLD)
    assert v.commands() == (0.0, 0.0)
    run(v, 0.5)
    assert abs(v.state.v) < 1e-3
    v.set_mode(AP_GUIDED)
    assert v.target is None and v.commands() == (0.0, 0.0)


def test_stock_preset_takes_about_two_seconds_to_ninety_percent():
    v = guided_armed(params=RoverParams.stock_rover())
    v.setpoint(rate_setpoint(1.0, 0.0))
    t = 0.0
    while v.state.v < 0.9:
        v.step(DT)
        t += DT
    assert 1.6 < t < 2.2


# --- setpoint decoding (ArduPilot Rover's rules) ---------------------------------------------
POSE = sp.Pose(1.0, 2.0, math.pi / 2)


@pytest.mark.parametrize("mask,frame,fields,expected", [
    (1511, 8, dict(vx=2.0, yaw_rate=0.3), sp.TurnRateSpeed(2.0, 0.3)),
    (1511, 8, dict(vx=-2.0, yaw_rate=0.3), sp.TurnRateSpeed(-2.0, 0.3)),          # reverse
    (1511, 1, dict(vx=2.0, yaw_rate=0.3), sp.TurnRateSpeed(2.0, 0.3)),
    (3559, 1, dict(vx=0.0, vy=1.0), sp.HeadingSpeed(math.pi / 2, 1.0)),
    (3559, 8, dict(vx=1.0), sp.HeadingSpeed(math.pi / 2, 1.0)),                   # body: + yaw
    (3559, 1, dict(vx=-1.0), sp.HeadingSpeed(math.pi, 1.0)),                      # no reverse
    (2535, 1, dict(vx=-1.0, yaw=0.5), sp.HeadingSpeed(0.5, -1.0)),                # vel + yaw
    (3580, 1, dict(x=5.0, y=-1.0), sp.PositionTarget(5.0, -1.0)),
    (3580, 7, dict(x=5.0, y=-1.0), sp.PositionTarget(6.0, 1.0)),
    (3580, 9, dict(x=1.0, y=0.0), sp.PositionTarget(1.0, 3.0)),
    (1535, 1, dict(yaw_rate=0.4), sp.TurnRateSpeed(0.0, 0.4)),
    (1511 | 16, 8, dict(vx=2.0, yaw_rate=0.3), sp.TurnRateSpeed(0.0, 0.3)),      # vy bit drops vx
    (1511 & ~(64 | 128), 8, dict(vx=2.0, yaw_rate=0.3), sp.Rejected("acceleration")),
    (1511, 6, dict(vx=2.0, yaw_rate=0.3), sp.Rejected("frame")),
    (1511, 8, dict(vx=math.nan, yaw_rate=0.3), sp.Rejected("non-finite")),
    (1511, 8, dict(vx=1.0, yaw_rate=math.inf), sp.Rejected("non-finite")),
    (1511, 8, dict(vx=1.0, yaw_rate=0.1, x=math.nan, yaw=math.nan), sp.TurnRateSpeed(1.0, 0.1)),
    (4095 & ~512, 1, dict(), sp.Rejected("nothing to do")),
])
def test_ardupilot_decoding(mask, frame, fields, expected):
    got = ardupilot.decode_setpoint(sp.Setpoint(frame, mask, **fields), POSE, max_speed=math.inf)
    if isinstance(expected, sp.HeadingSpeed):
        assert isinstance(got, sp.HeadingSpeed)
        assert got.heading == pytest.approx(expected.heading) and got.speed == expected.speed
    elif isinstance(expected, sp.PositionTarget):
        assert got.x == pytest.approx(expected.x) and got.y == pytest.approx(expected.y)
    else:
        assert got == expected


def test_velocity_speed_clamped_to_vehicle_limit():
    got = ardupilot.decode_setpoint(sp.Setpoint(1, 3559, vx=10.0), POSE, max_speed=4.0)
    assert got.speed == 4.0


# --- PX4 personality ---------------------------------------------------------------------------
def px4() -> Vehicle:
    return Vehicle(VehicleConfig(autopilot=px4_profile.PROFILE))


def stream(v: Vehicle, seconds: float, hz: float = 10.0, vx: float = 1.0) -> None:
    period = int(round(1.0 / hz / DT))
    for i in range(int(round(seconds / DT))):
        if i % period == 0:
            v.setpoint(sp.Setpoint(sp.FRAME_LOCAL_NED, 3559 | 1024 | 2048, vx=vx, yaw_rate=5.0))
        v.step(DT)


def test_px4_offboard_needs_proof_of_life():
    v = px4()
    assert v.set_mode(PX4_OFFBOARD) is Result.DENIED
    stream(v, 0.5)
    assert v.set_mode(PX4_OFFBOARD) is Result.DENIED        # only half a second
    stream(v, 0.6, hz=1.5)
    assert v.set_mode(PX4_OFFBOARD) is Result.DENIED        # too slow (< 2 Hz)
    stream(v, 1.05)
    assert v.set_mode(PX4_OFFBOARD) is Result.ACCEPTED
    assert v.custom_mode == 6 << 16
    assert px4_profile.PROFILE.requested_mode(256 + 4, 3) is None   # no aliasing
    assert px4_profile.PROFILE.requested_mode(4, 3) == PX4_HOLD


def test_px4_follows_velocity_vector_ignores_yaw_rate_and_falls_back_to_hold():
    v = px4()
    stream(v, 1.1)
    v.set_mode(PX4_OFFBOARD)
    v.arm(True)
    stream(v, 2.0)
    v.setpoint(sp.Setpoint(sp.FRAME_LOCAL_NED, 3559, vx=1.0))
    assert v.state.omega == pytest.approx(0.0, abs=1e-6)  # yaw_rate 5 ignored, heading north
    assert v.state.v == pytest.approx(1.0, rel=1e-3)
    v.pop_texts()
    run(v, 0.499)
    assert v.custom_mode == PX4_OFFBOARD
    run(v, 0.01)
    assert v.custom_mode == (4 << 16) | (3 << 24)
    assert OFFBOARD_LOST_TEXT in [t for _, t in v.pop_texts()]
    assert v.commands() == (0.0, 0.0)


# --- message intervals -----------------------------------------------------------------------
def test_stream_rates_cap_disable_default_and_alignment():
    s = StreamSchedule(loop_rate_hz=50)
    assert s.request(LOCAL_POSITION_NED, 25_000, 0).result == 0           # 40 Hz = 0.8 x 50
    reply = s.request(LOCAL_POSITION_NED, 20_000, 0)                      # 50 Hz: too fast
    assert reply.result == 2 and reply.text == "Requested rate for message ID 32 too fast"
    assert s.interval_us(LOCAL_POSITION_NED) == 25_000                    # old rate stays
    s.request(ATTITUDE, 25_000, 3_000)
    ticks = [t for t in range(0, 200_001, 1000) if LOCAL_POSITION_NED in (d := s.due(t))
             and d.index(ATTITUDE) < d.index(LOCAL_POSITION_NED)]
    assert ticks == list(range(25_000, 200_001, 25_000))                  # shared, ordered
    assert s.request(ATTITUDE, -1, 0).result == 0 and s.interval_us(ATTITUDE) == -1
    assert s.request(ATTITUDE, 0, 0).result == 0 and s.interval_us(ATTITUDE) == 1_000_000
    assert s.request(25, 100_000, 0).result == 2                          # not a stream we have
    assert s.request(math.nan, 100_000, 0).result == 4
    assert StreamSchedule(loop_rate_hz=63).request(32, 20_000, 0).result == 0


# --- telemetry impairments and the lockstep gate ---------------------------------------------
def test_telemetry_latency_dropout_and_noise_are_seeded():
    pipe = TelemetryPipe(TelemetryConfig(latency=0.1, dropout=0.3, noise_pos=0.5, seed=7))
    sent = 0
    for k in range(1000):
        sample = pipe.sample(k * 10_000, 1.0, 2.0, 3.1, 0.0, 0.0, 0.0)
        assert -math.pi < sample.yaw <= math.pi
        pipe.push(k * 10_000, LOCAL_POSITION_NED, sample)
        for _, s in pipe.release(k * 10_000):
            assert k * 10_000 - s.time_boot_ms * 1000 == 100_000             # exactly 0.1 s late
            sent += 1
    queued = len(pipe.release(10**12))
    assert 0.25 < pipe.dropped / 1000 < 0.35 and sent + pipe.dropped + queued == 1000
    assert queued <= 10
    a = TelemetryPipe(TelemetryConfig(noise_pos=0.5, seed=7)).sample(0, 0, 0, 0, 0, 0, 0)
    b = TelemetryPipe(TelemetryConfig(noise_pos=0.5, seed=7)).sample(0, 0, 0, 0, 0, 0, 0)
    assert a == b and a.x != 0.0


def test_lockstep_gate_and_pacer():
    gate = LockstepGate(timeout=0.25)
    assert not gate.engaged(0)
    gate.setpoint_arrived(1_000_000)
    assert gate.engaged(1_500_000) and not gate.engaged(2_000_000)
    gate.telemetry_sent(10.0)
    assert gate.deadline() == 10.25
    gate.setpoint_arrived(1_600_000)
    assert gate.deadline() is None
    pacer = Pacer(speedup=4.0)
    pacer.anchor(100.0, 2_000_000)
    assert pacer.vehicle_us(101.0) == 6_000_000 and pacer.wall_at(6_000_000) == 101.0
