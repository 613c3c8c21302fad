"""Plant model (eqs. (1)-(2) with first-order actuators) and the batch simulator.

The batch simulator must give the single-vehicle answer for every vehicle, whatever it is
batched with, and the paper-table's stacked trackers must give each controller's own answer.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.core.baselines import KanayamaGains, KanayamaTracker, PIDGains, PIDTracker
from companion.core.filter import FilterGains
from companion.core.limits import Limits
from companion.core.pzc import PZCGains, PZCTracker
from companion.core.trajectory import Ellipse
from companion.sim.batch import SimConfig, simulate
from companion.sim.experiment import TableConfig, run_table
from companion.sim.plant import RoverModel, RoverParams, RoverState


def test_exact_plant_step_agrees_with_fine_rk4():
    # The exact-actuator step (Simpson on closed forms) against the RK4 reference integrator.
    model = RoverModel(RoverParams(d_cen=0.3, w_c=5.0))
    a = b = RoverState(0.0, 0.0, 0.2, 0.5, -0.3)
    for k in range(2000):
        u, w = 1.0 + math.sin(0.01 * k), 0.8 * math.cos(0.013 * k)
        a = model.step(a, u, w, 1e-3)
        for _ in range(10):
            b = model.step_rk4(b, u, w, 1e-4)
    for key in ("x", "y", "yaw", "v", "omega"):
        assert getattr(a, key) == pytest.approx(getattr(b, key), abs=1e-8)


ARDUPILOT_LIKE = RoverParams(d_cen=0.2, w_c=3.0, w_c_yaw=8.0, max_speed=4.0, max_yaw_rate=2.1,
                             max_accel=1.0, max_yaw_accel=2.0, turn_speed_coupling=0.4)


@pytest.mark.parametrize("speed_turn", [0.0, 0.3])
def test_rate_limited_step_is_exact_against_fine_rk4(speed_turn):
    # Ramp-then-exponential closed forms per channel, through speed reversals, turn-rate
    # reversals at the limit and both couplings, against RK4 at a 20x finer step (the clamp
    # from the state at the start of each 1 ms step, as ``step`` takes it).
    model = RoverModel(ARDUPILOT_LIKE.with_(speed_turn_coupling=speed_turn))
    a = b = RoverState(0.0, 0.0, 0.3, 0.5, -0.2)
    clipped = 0
    for k in range(6000):
        u, w = 3.0 * math.sin(0.002 * k) + 1.0, 2.0 * math.cos(0.003 * k)
        a = model.step(a, u, w, 1e-3)
        uc, wc = model.clamp_command(u, w, b.omega, b.v)
        clipped += abs(wc) < min(abs(w), ARDUPILOT_LIKE.max_yaw_rate) - 1e-3
        for _ in range(20):
            b = model.step_rk4(b, uc, wc, 5e-5)
    for key in ("x", "y", "yaw", "v", "omega"):
        assert getattr(a, key) == pytest.approx(getattr(b, key), abs=1e-7)
    assert (clipped > 100) == (speed_turn > 0)          # the speed-side clamp did bind


def test_rate_limits_ramp_and_decel_differs_from_accel():
    model = RoverModel(RoverParams(w_c=50.0, max_accel=1.0, max_decel=2.0,
                                   max_yaw_accel=2.0, w_c_yaw=50.0))
    s = RoverState()
    for _ in range(1000):                        # 1 s at +1 m/s^2, +2 rad/s^2 from rest
        s = model.step(s, 5.0, 5.0, 1e-3)
    assert s.v == pytest.approx(1.0, abs=1e-9) and s.omega == pytest.approx(2.0, abs=1e-9)
    for _ in range(250):                         # braking at 2 m/s^2 while |v| shrinks
        s = model.step(s, 0.0, 2.0, 1e-3)
    assert s.v == pytest.approx(0.5, abs=1e-9)


def test_pure_delay_shifts_the_response_by_exactly_the_delay():
    plain = RoverModel(RoverParams(w_c=4.0))
    late = RoverModel(RoverParams(w_c=4.0, speed_delay=0.1, yaw_delay=0.05))
    a, b = RoverState(), RoverState()
    va, vb, wb = [], [], []
    for _ in range(1000):
        a, b = plain.step(a, 1.0, 1.0, 1e-3), late.step(b, 1.0, 1.0, 1e-3)
        va.append(a.v)
        vb.append(b.v)
        wb.append(b.omega)
    assert vb[:100] == [0.0] * 100 and wb[:50] == [0.0] * 50
    assert vb[100:] == pytest.approx(va[:900], abs=1e-12)
    assert wb[50:] == pytest.approx([x for x in va[:950]], abs=1e-12)   # same bandwidth
    with pytest.raises(ValueError, match="fixed step"):
        late.step(b, 1.0, 1.0, 2e-3)


def test_skid_steer_coupling_takes_speed_while_turning():
    model = RoverModel(RoverParams(w_c=20.0, max_speed=4.0, max_yaw_rate=2.0,
                                   turn_speed_coupling=0.5))
    s = RoverState()
    for _ in range(3000):
        s = model.step(s, 10.0, 2.0, 1e-3)       # full turn rate: half the top speed is left
    assert s.omega == pytest.approx(2.0) and s.v == pytest.approx(2.0, abs=1e-6)
    for _ in range(3000):
        s = model.step(s, 10.0, 1.0, 1e-3)       # half the turn rate: three quarters
    assert s.v == pytest.approx(3.0, abs=1e-6)


def test_skid_steer_coupling_takes_turn_rate_at_speed():
    # Full speed leaves (1 - c_w) of the turn rate, half of top speed (1 - c_w / 2); at rest
    # the whole turn rate; the speed itself is not touched by c_w.
    model = RoverModel(RoverParams(w_c=20.0, w_c_yaw=20.0, max_speed=4.0, max_yaw_rate=2.0,
                                   speed_turn_coupling=0.15))
    s = RoverState()
    for _ in range(3000):
        s = model.step(s, 10.0, 5.0, 1e-3)
    assert s.v == pytest.approx(4.0) and s.omega == pytest.approx(2.0 * 0.85, abs=1e-6)
    for _ in range(3000):
        s = model.step(s, 2.0, -5.0, 1e-3)
    assert s.v == pytest.approx(2.0) and s.omega == pytest.approx(-2.0 * 0.925, abs=1e-6)
    for _ in range(3000):
        s = model.step(s, 0.0, 5.0, 1e-3)
    assert s.v == pytest.approx(0.0, abs=1e-9) and s.omega == pytest.approx(2.0, abs=1e-6)
    assert not model.params.is_paper and RoverParams(speed_turn_coupling=0.0).is_paper
    # Many vehicles at once, each with its own share.
    shares = np.array([0.0, 0.15, 1.0])
    _, w = RoverModel(RoverParams(max_speed=4.0, max_yaw_rate=2.0,
                                  speed_turn_coupling=shares), 3).clamp_command(
        np.full(3, 4.0), np.full(3, 3.0), np.zeros(3), np.array([4.0, -4.0, 2.0]))
    assert w == pytest.approx([2.0, 1.7, 1.0])


def test_robust_ensemble_perturbs_and_stacks_the_turn_rate_coupling():
    # The robust tuner's neighbours carry c_w (+- the coupling spread, within [0, 1]) into the
    # stacked batch parameters, per vehicle.
    from companion.sim.robust.config import Spread
    from companion.sim.robust.ensemble import ensemble, stack_params
    vehicle = RoverParams(w_c=3.0, max_speed=3.0, max_yaw_rate=2.1, max_accel=1.0,
                          turn_speed_coupling=0.3, speed_turn_coupling=0.1)
    members = ensemble(vehicle, 8, Spread(coupling=0.15), 0.025, seed=2)
    shares = [m.speed_turn_coupling for m in members]
    assert shares[0] == 0.1 and shares[2] == 0.0                # the fixed corner: -0.15, clipped
    assert all(0.0 <= c <= 0.25 + 1e-12 for c in shares) and len(set(shares[3:])) == 6
    assert max(shares) > 0.1 and min(shares[3:]) < 0.1
    stacked = stack_params(members, 2, 1)
    assert list(stacked.speed_turn_coupling) == [c for c in shares for _ in range(2)]


def test_batch_vehicle_model_equals_one_vehicle_each():
    # Per-vehicle delays, limits and couplings in one batch give each vehicle's own answer.
    d_cen, w_c = np.array([0.0, 0.2, 0.3]), np.array([3.0, 3.0, 5.0])
    accel, delay = np.array([1.0, 1.0, 2.0]), np.array([0.0, 0.05, 0.1])
    speed_turn = np.array([0.0, 0.15, 0.4])
    common = dict(max_speed=4.0, max_yaw_rate=2.1, max_yaw_accel=2.0, yaw_delay=0.04,
                  turn_speed_coupling=0.4)
    batch = RoverModel(RoverParams(d_cen=d_cen, w_c=w_c, max_accel=accel, speed_delay=delay,
                                   speed_turn_coupling=speed_turn, **common), 3)
    singles = [RoverModel(RoverParams(d_cen=float(d_cen[i]), w_c=float(w_c[i]),
                                      max_accel=float(accel[i]), speed_delay=float(delay[i]),
                                      speed_turn_coupling=float(speed_turn[i]), **common))
               for i in range(3)]
    z = np.zeros(3)
    sb, ss = RoverState(z, z, z, z, z), [RoverState() for _ in range(3)]
    for k in range(3000):
        u, w = 3.0 * math.sin(0.002 * k) + 1.0, 2.0 * math.cos(0.003 * k)
        sb = batch.step(sb, u + z, w + z, 1e-3)
        ss = [m.step(s, u, w, 1e-3) for m, s in zip(singles, ss, strict=True)]
    for key in ("x", "y", "yaw", "v", "omega"):
        assert getattr(sb, key) == pytest.approx([getattr(s, key) for s in ss], abs=1e-12)


@pytest.mark.parametrize("share", [0.0, -0.5, 0.7])
def test_channel_response_is_the_full_models(share):
    from companion.sim.response import respond
    params = ARDUPILOT_LIKE.with_(speed_delay=0.05, yaw_delay=0.02, speed_turn_coupling=0.2,
                                  speed_overshoot=0.3, speed_overshoot_s=0.8,
                                  yaw_overshoot=share, yaw_overshoot_s=0.6)
    t = np.arange(0.0, 20.0, 0.025)
    u = np.where(t % 10 < 5, 2.0, -1.0)
    w = np.where(t % 7 < 3, 1.5, -1.5)
    v, om = respond(params, t, u, w, n=2, dt=0.005)
    model, s, k = RoverModel(params), RoverState(), 0
    vs, ws = [], []
    for i in range(int(20.0 / 0.005) + 1):
        while k + 1 < len(t) and t[k + 1] <= i * 0.005 + 1e-12:
            k += 1
        vs.append(s.v)
        ws.append(s.omega)
        s = model.step(s, u[k], w[k], 0.005)
    idx = np.minimum((t / 0.005 + 1e-9).astype(int), len(vs) - 1)
    assert v[:, 1] == pytest.approx(np.array(vs)[idx], abs=1e-12)
    assert om[:, 0] == pytest.approx(np.array(ws)[idx], abs=1e-12)


@pytest.mark.parametrize("share", [-0.5, 0.7])
def test_the_heading_integrates_a_two_time_scale_turn_rate(share):
    # The rate loop's two time scales (yaw_overshoot): the heading a step gives is the integral
    # of the turn rate the model reports (overshoot_integral), and 20 ms steps agree with
    # 0.1 ms ones to the slow state's approximation (the channel's output at its step mean).
    params = ARDUPILOT_LIKE.with_(yaw_overshoot=share, yaw_overshoot_s=0.6)
    coarse, fine = RoverModel(params), RoverModel(params)
    a = b = RoverState(0.0, 0.0, 0.3, 0.5, -0.2)
    integral, peak = 0.0, 0.0
    for k in range(400):                           # 8 s of turn-rate steps, +-1.5 rad/s
        w = 1.5 if (k // 100) % 2 == 0 else -1.5
        a = coarse.step(a, 1.0, w, 0.02)
        for _ in range(200):
            before = b.omega
            b = fine.step(b, 1.0, w, 1e-4)
            integral += 0.5 * (before + b.omega) * 1e-4
        peak = max(peak, abs(b.omega))
    assert b.yaw - 0.3 == pytest.approx(integral, abs=1e-6)
    assert a.omega == pytest.approx(b.omega, abs=1e-3)
    assert a.yaw == pytest.approx(b.yaw, abs=1e-3)
    # the share beyond the change at once: overshoots the 1.5 rad/s, or comes late to it
    assert (peak > 1.5 + 0.3) == (share > 0)


def test_an_overshooting_turn_rate_is_capped_by_what_the_motors_give():
    # A rate loop whose feed-forward over-drives (yaw_overshoot 0.8) overshoots a 1.2 rad/s
    # target well past it at rest; at speed the mixer leaves a skid-steer rover less turn rate
    # (speed_turn_coupling: 2.1 (1 - 0.5) = 1.05 at full speed), and the overshoot stops there.
    # The heading is still the integral of the turn rate reported, 20 ms steps as 0.1 ms ones.
    params = ARDUPILOT_LIKE.with_(yaw_overshoot=0.8, yaw_overshoot_s=0.6, turn_speed_coupling=0.0,
                                  speed_turn_coupling=0.5, max_yaw_accel=math.inf)
    peaks = {}
    for speed in (0.0, 4.0):
        coarse, fine = RoverModel(params), RoverModel(params)
        a = b = RoverState(v=speed)
        integral, peak = 0.0, 0.0
        for k in range(150):                       # 3 s: a turn-rate step, then back to 0
            w = 1.2 if k < 75 else 0.0
            a = coarse.step(a, speed, w, 0.02)
            for _ in range(200):
                before = b.omega
                b = fine.step(b, speed, w, 1e-4)
                integral += 0.5 * (before + b.omega) * 1e-4
            peak = max(peak, abs(a.omega))
            top = coarse.tops(0.0, a.v)[1]
            assert abs(a.omega) <= top + 1e-12
        assert b.yaw == pytest.approx(integral, abs=2e-5)    # a kink where the cap starts
        assert a.yaw == pytest.approx(b.yaw, abs=2e-3)
        peaks[speed] = peak
    assert peaks[0.0] > 1.2 + 0.5                  # at rest: the overshoot, whole
    assert peaks[4.0] == pytest.approx(1.05)       # at speed: capped, held


def test_d_cen_moves_the_tracked_point_sideways_when_turning():
    # eq. (1): pure rotation (v = 0) moves p by d_cen omega at right angles to the heading.
    model = RoverModel(RoverParams(d_cen=0.5, w_c=20.0))
    vx, vy = model.velocity(RoverState(0.0, 0.0, 0.0, 0.0, 2.0))
    assert (vx, vy) == pytest.approx((0.0, 1.0))


def test_actuator_is_first_order_at_w_c():
    model = RoverModel(RoverParams(w_c=1.2))
    s = RoverState()
    for _ in range(1000):
        s = model.step(s, 1.0, 0.0, 1e-3)
    assert s.v == pytest.approx(1.0 - math.exp(-1.2), rel=1e-9)


def test_stock_rover_limits_speed_turn_rate_and_acceleration():
    model = RoverModel(RoverParams.stock_rover())
    s = RoverState()
    speeds = []
    for _ in range(10000):
        s = model.step(s, 10.0, 10.0, 1e-3)
        speeds.append(s.v)
    assert max(np.diff(speeds)) / 1e-3 <= 1.0 + 1e-6     # 1 m/s^2
    assert s.v <= 4.0 + 1e-9 and s.omega <= math.radians(120.0) + 1e-9


def _single(tracker, f_r, d_cen, rate, duration=8.0):
    return simulate(tracker, RoverParams.paper(d_cen=d_cen), Ellipse.paper(f_r), None,
                    SimConfig(duration=duration, control_rate=rate))


@pytest.mark.parametrize("make", [
    lambda n: PZCTracker(FilterGains(), PZCGains(), Limits(3.0, 4.0), n=n),
    lambda n: PZCTracker(FilterGains(200.0, 40.0), PZCGains(2.0, 3.0, velocity_ff=True,
                                                           heading_rate_ff=True, accel_ff=0.1), n=n),
    lambda n: PIDTracker(PIDGains(), n=n),
    lambda n: KanayamaTracker(KanayamaGains(), n=n),
])
def test_batch_and_single_vehicle_give_the_same_answer(make):
    f_r = np.array([0.04, 0.12, 0.12])
    d_cen = np.array([0.0, 0.3, 0.6])
    batch = simulate(make(3), RoverParams(d_cen=d_cen, w_c=20.0), Ellipse.paper(f_r), 3,
                     SimConfig(duration=8.0, control_rate=50.0))
    for i in range(3):
        one = _single(make(None), float(f_r[i]), float(d_cen[i]), 50.0)
        assert batch.f_cost[i] == pytest.approx(one.f_cost, rel=1e-9)
        assert batch.steady_rms[i] == pytest.approx(one.steady_rms, rel=1e-9)


def test_controller_rate_holds_the_command_between_updates():
    # 10 Hz control on a 1 ms plant grid: 100 substeps with the command held (zero-order hold).
    config = SimConfig(duration=4.0, control_rate=10.0)
    assert config.substeps == 100
    result = _single(PZCTracker(FilterGains(30.0, 10.0), PZCGains(1.0, 1.0)), 0.04, 0.0, 10.0, 4.0)
    assert math.isfinite(result.f_cost)


def test_paper_table_cells_equal_single_vehicle_runs():
    tuned = (FilterGains(300.0, 50.0), PZCGains(1.0, 4.0, velocity_ff=True, heading_rate_ff=True))
    config = TableConfig(rate_hz=100.0, duration=6.0, scenarios=((0.04, 0.0), (0.12, 0.6)),
                         trace_every=0.1)
    table = run_table(config, tuned, "test")
    makers = {"pzc": lambda: PZCTracker(FilterGains(), PZCGains()),
              "pzc_tuned": lambda: PZCTracker(*tuned),
              "pid": lambda: PIDTracker(PIDGains()),
              "kanayama": lambda: KanayamaTracker(KanayamaGains())}
    for name, make in makers.items():
        for i, (f_r, d_cen) in enumerate(config.scenarios):
            one = _single(make(), f_r, d_cen, 100.0, 6.0)
            # The PID differentiates phi_ref = atan2(u_p); when u_p passes near zero (d_cen 0.6
            # here, about t = 4.5 s) that derivative amplifies last-bit differences between
            # math.atan2 and numpy.arctan2 to 1e-4. Everything else agrees to rounding.
            rel = 1e-3 if name == "pid" else 1e-9
            assert table.f_cost[name][i] == pytest.approx(one.f_cost, rel=rel), name
    # traces: one column per scenario; filter errors e_f = measurement - estimate, 0 where
    # the tracker flies the raw measurement (no filter), NaN only before the first step
    assert table.traces["pzc"]["x"].shape[1] == 2
    assert np.all(table.traces["pid"]["ex"][1:] == 0.0)
    assert np.all(np.isfinite(table.traces["pzc"]["ex"][1:]))
    assert np.any(table.traces["pzc"]["ex"][1:] != 0.0)


def test_single_vehicle_trace_records():
    result = simulate(PZCTracker(), RoverParams.paper(), Ellipse.paper(0.12), None,
                      SimConfig(duration=1.0, control_rate=100.0, trace_every=0.1))
    assert result.trace["x"].shape == (10,) and np.all(np.isfinite(result.trace["ex"]))


def test_tick_aligned_schedule_is_ardupilots_20_20_20_40_ms():
    config = SimConfig(duration=2.0, control_rate=40.0, tick=0.02, max_plant_dt=0.005)
    times, substeps, h = config.schedule()
    gaps = np.round(np.diff(times) * 1000).astype(int)
    assert set(gaps) == {20, 40} and len(times) == 80
    assert h == pytest.approx(0.005) and sum(substeps) * h == pytest.approx(2.0)


class _Bang:
    """A tracker that slams the yaw rate from one limit to the other every step (a relay)."""

    def __init__(self, amplitude: float):
        self.amplitude, self.sign = amplitude, 1.0

    def reset(self):
        self.sign = 1.0

    def step(self, t, meas, ref):
        from companion.core.signals import Command
        self.sign = -self.sign
        return Command(1.0, self.sign * self.amplitude, 0.0, 0.0)


def test_chatter_metrics_see_a_relay_and_not_a_steady_command():
    params = RoverParams(w_c=5.0, max_speed=4.0, max_yaw_rate=2.0)
    config = SimConfig(duration=4.0, control_rate=40.0)
    relay = simulate(_Bang(2.0), params, Ellipse.paper(0.04), None, config)
    assert relay.yaw_at_limit == pytest.approx(1.0)
    assert relay.yaw_rate_tv == pytest.approx(4.0 * 40.0, rel=0.02)    # 4 rad/s per step
    assert relay.speed_tv == 0.0
    calm = simulate(_Bang(0.5), params, Ellipse.paper(0.04), None, config)
    assert calm.yaw_at_limit == 0.0
