"""Plant model (eqs. (1)-(2) with first-order actuators) and the batch simulator.

The batch simulator must give the single-vehicle answer for every vehicle, whatever it is
batched with, and the paper-table's stacked trackers must give each controller's own answer.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.core.baselines import KanayamaGains, KanayamaTracker, PIDGains, PIDTracker
from companion.sim.batch import SimConfig, simulate
from companion.sim.experiment import TableConfig, run_table
from companion.core.filter import FilterGains
from companion.core.limits import Limits
from companion.sim.plant import RoverModel, RoverParams, RoverState
from companion.core.pzc import PZCGains, PZCTracker
from companion.core.trajectory import Ellipse


def test_exact_plant_step_agrees_with_fine_rk4():
    # The exact-actuator step (Simpson on closed forms) against RK4 with an (inactive) accel limit.
    exact = RoverModel(RoverParams(d_cen=0.3, w_c=5.0))
    rk4 = RoverModel(RoverParams(d_cen=0.3, w_c=5.0, max_accel=1e9))
    a = b = RoverState(0.0, 0.0, 0.2, 0.5, -0.3)
    for k in range(2000):
        u, w = 1.0 + math.sin(0.01 * k), 0.8 * math.cos(0.013 * k)
        a = exact.step(a, u, w, 1e-3)
        for _ in range(10):
            b = rk4.step(b, u, w, 1e-4)
    for key in ("x", "y", "yaw", "v", "omega"):
        assert getattr(a, key) == pytest.approx(getattr(b, key), abs=1e-8)


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
    # traces: one column per scenario, filter errors only where there is a filter
    assert table.traces["pzc"]["x"].shape[1] == 2
    assert np.all(np.isnan(table.traces["pid"]["ex"]))
    assert np.all(np.isfinite(table.traces["pzc"]["ex"]))


def test_single_vehicle_trace_records():
    result = simulate(PZCTracker(), RoverParams.paper(), Ellipse.paper(0.12), None,
                      SimConfig(duration=1.0, control_rate=100.0, trace_every=0.1))
    assert result.trace["x"].shape == (10,) and np.all(np.isfinite(result.trace["ex"]))
