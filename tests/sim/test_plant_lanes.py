"""The compiled plant step (companion.sim.plant_lanes) is RoverModel's numpy step, to rounding.

Batch simulation (the robust tuner, calibrate's tunes) steps thousands of vehicles at once;
numba compiles one pass over them where it is installed (``plant_lanes.LaneModel``), and
``RoverModel`` runs the numpy step, the reference (and what runs without numba). Each case drives vehicles
with different parameters through every piece the step has: PX4's course loop, per-vehicle
delays, rate limits (and none), both couplings, a turning radius, the lateral-acceleration
limit, the speed overshoot (one that never comes back too) and the turn rate's two time scales.
"""

from __future__ import annotations

import math
import platform

import numpy as np
import pytest

from companion.sim import plant_lanes
from companion.sim.plant import RoverModel, RoverParams, RoverState

N = 48


def _params(case: str, rng: np.random.Generator) -> RoverParams:
    u = lambda lo, hi: rng.uniform(lo, hi, N)  # noqa: E731
    accel = u(0.3, 3.0)
    accel[::5] = np.inf                                  # no rate limit on some
    common = dict(d_cen=u(0.0, 0.3), w_c=u(0.8, 6.0), w_c_yaw=u(1.0, 12.0), max_speed=u(1.5, 4.0),
                  max_yaw_rate=u(0.8, 3.0), max_accel=accel, max_decel=u(0.3, 4.0),
                  max_yaw_accel=u(1.0, 8.0), max_yaw_decel=u(1.0, 10.0),
                  speed_delay=rng.choice([0.0, 0.02, 0.06, 0.1], N),
                  yaw_delay=rng.choice([0.0, 0.04, 0.08], N))
    if case == "skid":
        return RoverParams(**common, turn_speed_coupling=u(0.0, 0.6),
                           speed_turn_coupling=u(0.0, 0.5))
    if case == "car":
        tau = u(0.3, 3.0)
        tau[::4] = np.inf                                # an over-drive that never comes back
        return RoverParams(**common, min_turn_radius=u(0.2, 2.0), max_lat_accel=u(0.4, 1.5),
                           speed_overshoot=u(0.0, 0.7), speed_overshoot_s=tau,
                           yaw_overshoot=u(-0.4, 0.6), yaw_overshoot_s=u(0.3, 2.0))
    assert case == "px4"
    return RoverParams(**common, course_gain=u(1.5, 5.0), min_turn_radius=u(0.3, 1.0),
                       speed_overshoot=u(0.0, 0.4), speed_overshoot_s=u(0.5, 8.0))


def _commands(case: str, k: int, rng_phase: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smooth commands with steps and reversals, a different phase per vehicle."""
    t = 0.02 * k + rng_phase
    a = 2.0 * np.sin(0.5 * t) + np.where(np.sin(0.11 * t) > 0.6, 1.5, 0.0)
    b = 1.5 * np.sin(0.9 * t + 1.0) + np.where(np.cos(0.23 * t) > 0.7, -2.0, 0.0)
    return a, b


def _fly(case: str, compiled: bool, steps: int = 1500, swap_at: int = 700,
         loop=None) -> list[np.ndarray]:
    rng = np.random.default_rng({"skid": 1, "car": 2, "px4": 3}[case])
    params = _params(case, rng)
    phase = rng.uniform(0, 20, N)
    model = plant_lanes.LaneModel(params, N, loop) if compiled else RoverModel(params, N)
    zero = np.zeros(N)
    s = RoverState(zero, zero, zero, zero, zero)          # v_slow, w_slow plain 0.0
    trace = []
    for k in range(steps):
        if k == swap_at:    # a state the model did not make (copies): stepped as well
            s = RoverState(*(np.array(getattr(s, f), dtype=float) for f in
                             ("x", "y", "yaw", "v", "omega", "v_slow", "w_slow")),
                           w_lag=None if s.w_lag is None else np.array(s.w_lag, dtype=float))
        a, b = _commands(case, k, phase)
        s = model.step_vector(s, a, b, 0.02) if case == "px4" else model.step(s, a, b, 0.02)
        lag = () if case != "car" else (s.w_lag,)   # the turn-rate lag's own output (capped)
        trace.append(np.stack([np.broadcast_to(v, (N,)) for v in
                               (s.x, s.y, s.yaw, s.v, s.omega, s.v_slow, s.w_slow) + lag]))
    return trace


needs_numba = pytest.mark.skipif(not plant_lanes.available(),
                                 reason="numba is not installed here: the numpy step runs")


@needs_numba
@pytest.mark.parametrize("case", ["skid", "car", "px4"])
def test_compiled_step_is_the_numpy_step(case):
    fast = np.array(_fly(case, compiled=True))
    ref = np.array(_fly(case, compiled=False))
    assert np.all(np.isfinite(ref))
    # the vehicles moved, turned both ways and hit their limits on the way
    assert np.ptp(ref[:, 0]) > 5.0 and np.ptp(ref[:, 4]) > 1.0
    if case == "car":       # and some overshooting turn rates met the motors' cap
        assert np.any(np.abs(ref[:, 7] - ref[:, 4]) > 0.05)
    scale = 1.0 + np.abs(ref)
    assert np.max(np.abs(fast - ref) / scale) < 1e-10


@needs_numba
def test_compiled_step_keeps_the_measured_heading_trig():
    """The step hands RoverModel the new heading's cosine and sine (measure reuses them)."""
    rng = np.random.default_rng(5)
    model = plant_lanes.LaneModel(_params("skid", rng), N)
    zero = np.zeros(N)
    s = model.step(RoverState(zero, zero, zero, zero, zero), np.ones(N), np.full(N, 0.8), 0.02)
    for _ in range(50):
        s = model.step(s, np.ones(N), np.full(N, 0.8), 0.02)
    meas = model.measure(s)
    c, sn = np.cos(s.yaw), np.sin(s.yaw)
    assert np.allclose(meas.vx, s.v * c - model.params.d_cen * s.omega * sn, atol=1e-12)
    assert np.allclose(meas.vy, s.v * sn + model.params.d_cen * s.omega * c, atol=1e-12)


@pytest.mark.parametrize("case", ["car", "px4"])
def test_the_loop_as_python_is_the_numpy_step(case):
    """The per-vehicle arithmetic itself (what numba compiles), run as plain Python."""
    loop = getattr(plant_lanes._compiled, "py_func", None) or plant_lanes._loop
    if not plant_lanes.available():
        pytest.skip("numba is not installed here: there is no compiled step to stand for")
    python = np.array(_fly(case, compiled=True, steps=120, swap_at=60, loop=loop))
    ref = np.array(_fly(case, compiled=False, steps=120, swap_at=60))
    assert np.max(np.abs(python - ref) / (1.0 + np.abs(ref))) < 1e-10


def test_the_paper_plant_and_one_vehicle_keep_numpy_and_floats():
    """Nothing tunes on the paper's exact linear step, and one vehicle runs on floats."""
    assert type(plant_lanes.batch_model(RoverParams.paper(), 8)) is RoverModel
    assert type(plant_lanes.batch_model(RoverParams.stock_rover(), None)) is RoverModel
    one = plant_lanes.batch_model(RoverParams.stock_rover(), None)
    s = one.step(RoverState(), 1.0, 0.5, 0.02)
    assert isinstance(s.x, float) and math.isfinite(s.x)


@pytest.mark.skipif(platform.machine().lower() not in {"x86_64", "amd64", "aarch64", "arm64"},
                    reason="numba has no wheels here: the numpy step runs")
def test_numba_compiles_the_step_where_it_has_wheels():
    """pyproject installs numba on these machines; without it a robust tune is about 1.4x
    slower (benchmarks/bench_tune.py)."""
    assert plant_lanes.available()
    assert isinstance(plant_lanes.batch_model(RoverParams.stock_rover(), 8), plant_lanes.LaneModel)


def _respond_case(case: str):
    rng = np.random.default_rng({"skid": 11, "car": 12}[case])
    params = _params(case, rng)
    t = np.cumsum(rng.choice([0.02, 0.02, 0.02, 0.04], 2500))
    speed = 2.0 * np.sin(0.3 * t) + np.where(np.sin(0.07 * t) > 0.5, 1.2, -0.3)
    turn = 1.2 * np.sin(0.8 * t + 0.5) + np.where(np.cos(0.19 * t) > 0.6, -1.5, 0.0)
    return params, t, speed, turn


@needs_numba
@pytest.mark.parametrize("case", ["skid", "car"])
def test_compiled_respond_is_the_numpy_respond(case):
    """Identification's model (sim.response.respond: both channels, coupled through their
    clamps, with delays and overshoots), compiled against numpy's step loop."""
    from companion.sim.response import respond
    params, t, speed, turn = _respond_case(case)
    fast = respond(params, t, speed, turn, N, 0.01, v0=0.3, omega0=-0.2)
    ref = respond(params, t, speed, turn, N, 0.01, v0=0.3, omega0=-0.2, compiled=False)
    assert np.ptp(ref[0]) > 2.0 and np.ptp(ref[1]) > 1.0
    for a, b in zip(fast, ref, strict=True):
        assert a.shape == b.shape == (len(t), N)
        assert np.max(np.abs(a - b) / (1.0 + np.abs(b))) < 1e-10


@needs_numba
def test_respond_loop_as_python_is_the_numpy_respond():
    from companion.sim import response
    params, t, speed, turn = _respond_case("car")
    t, speed, turn = t[:300], speed[:300], turn[:300]
    python_loop = plant_lanes._respond_compiled.py_func
    saved = plant_lanes.respond_series

    def with_python(*args, **kwargs):
        return saved(*args, loop=python_loop, **kwargs)

    plant_lanes.respond_series = with_python
    try:
        python = response.respond(params, t, speed, turn, N, 0.01)
    finally:
        plant_lanes.respond_series = saved
    ref = response.respond(params, t, speed, turn, N, 0.01, compiled=False)
    for a, b in zip(python, ref, strict=True):
        assert np.max(np.abs(a - b) / (1.0 + np.abs(b))) < 1e-10
