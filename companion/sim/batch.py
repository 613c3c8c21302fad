"""Closed-loop simulation of one rover (floats) or thousands at once (numpy arrays).

The plant (:mod:`companion.sim.plant`) is integrated with RK4 on a fine fixed step (1 ms or finer);
the trackers run at their own rate (1 kHz down to 10 Hz or less) on the sampled pose, and their
command is held (zero-order hold) until the next control step, as on a real autopilot link.
The very same tracker objects run here and in the live MAVLink loop (a vehicle with PX4's
velocity-vector interface, ``RoverParams.velocity_vector``, is sent the command's u_p); ``n=None`` simulates one
vehicle on Python floats, ``n=k`` simulates k vehicles on arrays, each tracker owning a slice.

Metrics (Section 5.3), per vehicle, integrated on the plant step:
    f_cost     = sqrt( int_0^T |p_ref - p|^2 dt )
    steady_rms = sqrt( mean over t in [T/2, T] of |p_ref - p|^2 )
and what a real vehicle's inner loops feel of the commands (the chatter a limit cycle shows):
    speed_tv, yaw_rate_tv = total variation of the speed / yaw-rate commands per second
    yaw_at_limit          = share of control steps in [T/2, T] with |omega_ref| at the limit

``SimConfig.tick`` reproduces how an autopilot delivers telemetry: each sample leaves on the
first scheduler tick at or after its due time, so 40 Hz on ArduPilot's 50 Hz loop comes at
20, 20, 20, 40 ms intervals and the tracker steps on those instants.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.signals import Measurement, Num, Reference
from ..core.tracker import Tracker
from ..core.trajectory import Trajectory
from .plant import RoverParams, RoverState
from .plant_lanes import batch_model


@dataclass(frozen=True)
class SimConfig:
    duration: float = 60.0          # s
    control_rate: float = 1000.0    # Hz
    max_plant_dt: float = 1e-3      # s; the plant step is the largest divisor of the control period below this
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)   # x, y, yaw at rest (the paper's start, our choice)
    trace_every: float | None = None   # s between trace samples; None records no trace
    noise_pos: float = 0.0          # m, std of white position noise on the measurement
    noise_yaw: float = 0.0          # rad
    seed: int = 0
    tick: float | None = None       # s, scheduler tick the samples are aligned to (ArduPilot: 0.02)
    yaw_rate_limit: float | None = None   # rad/s for yaw_at_limit; None: the vehicle's max_yaw_rate
    # (total, start): these n vehicles are [start, start + n) of a batch of ``total`` split
    # across processes; each draws the whole batch's noise and keeps its own slice, so every
    # vehicle sees the noise it would see in the whole batch (None: the batch is all there is)
    noise_slice: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        for name in ("duration", "control_rate", "max_plant_dt"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, not {value!r}")

    @property
    def control_period(self) -> float:
        return 1.0 / self.control_rate

    @property
    def substeps(self) -> int:
        return max(1, math.ceil(self.control_period / self.max_plant_dt - 1e-9))

    def schedule(self) -> tuple[list[float], list[int], float]:
        """Control instants, plant substeps after each, and the plant step h."""
        n_control = int(round(self.duration * self.control_rate))
        if self.tick is None:
            h = self.control_period / self.substeps
            return [k * self.control_period for k in range(n_control)], \
                [self.substeps] * n_control, h
        tick_us = int(round(self.tick * 1e6))
        per_tick = max(1, math.ceil(self.tick / self.max_plant_dt - 1e-9))
        due_us = [int(round(k * self.control_period * 1e6)) for k in range(n_control)]
        sent = sorted({-(-d // tick_us) * tick_us for d in due_us})
        end_us = int(round(self.duration * 1e6))
        sent = [u for u in sent if u < end_us]
        ticks = [(b - a) // tick_us for a, b in zip(sent, sent[1:] + [end_us], strict=True)]
        return [u * 1e-6 for u in sent], [per_tick * t for t in ticks], self.tick / per_tick


@dataclass
class SimResult:
    f_cost: Num
    steady_rms: Num
    trace: dict[str, np.ndarray] = field(default_factory=dict)
    speed_tv: Num = 0.0             # m/s per s: total variation of the speed commands
    yaw_rate_tv: Num = 0.0          # rad/s per s
    yaw_at_limit: Num = 0.0         # share of the second half's control steps at the limit


def _take(obj: Any, sl: slice | None) -> Any:
    """The slice ``sl`` of every field of a signal dataclass."""
    return type(obj)(*[getattr(obj, name)[sl] for name in obj.__slots__])


def simulate(trackers: Tracker | Sequence[tuple[Tracker, slice]], params: RoverParams,
             reference: Trajectory, n: int | None = None, config: SimConfig = SimConfig(),
             progress: Callable[[float], None] | None = None) -> SimResult:
    """Run the closed loop for ``config.duration`` seconds.

    ``trackers`` is one tracker for all vehicles, or ``(tracker, slice)`` pairs that split the
    ``n`` vehicles between several trackers (each built with ``n = slice length``).
    ``progress(fraction)`` is called about a hundred times.
    """
    groups: list[tuple[Tracker, slice | None]] = (
        list(trackers) if isinstance(trackers, Sequence) else [(trackers, None)])
    for tracker, _ in groups:
        tracker.reset()
    model = batch_model(params, n)
    zero = 0.0 if n is None else np.zeros(n)
    x0, y0, yaw0 = config.start
    state = RoverState(x0 + zero, y0 + zero, yaw0 + zero, zero, zero)
    rng = np.random.default_rng(config.seed)
    noisy = config.noise_pos > 0 or config.noise_yaw > 0
    shape: int | None = n
    noise_part = slice(None)
    if config.noise_slice is not None and n is not None:
        total, first = config.noise_slice
        shape, noise_part = total, slice(first, first + n)

    times, substeps_after, h = config.schedule()
    n_control = len(times)
    half = sum(substeps_after) // 2
    limit = config.yaw_rate_limit if config.yaw_rate_limit is not None else params.max_yaw_rate
    at_limit_from = 0.98 * np.asarray(limit, dtype=float) if _ops_finite(limit) else None
    tv_speed = tv_yaw = at_limit = zero
    at_limit_steps = 0
    cost = zero
    steady = zero
    trace_stride = None if config.trace_every is None else max(1, round(config.trace_every / h))
    trace: dict[str, list] = {}
    report_every = max(1, n_control // 100)
    speed_cmd = yaw_rate_cmd = zero
    last_speed = last_yaw_rate = zero      # the previous step's commands (for the variation)
    step_index = 0
    # PX4's interface: the vehicle gets the velocity vector u_p, not (speed, turn rate)
    vector = params.velocity_vector
    ux: Any = zero   # Num: a float for one vehicle, filled slice by slice for groups
    uy: Any = zero

    for k in range(n_control):
        t = times[k]
        substeps = substeps_after[k]
        ref = reference.sample(t)
        meas = model.measure(state)
        if noisy:
            if shape is None:
                meas.x = meas.x + config.noise_pos * rng.standard_normal()
                meas.y = meas.y + config.noise_pos * rng.standard_normal()
                meas.yaw = meas.yaw + config.noise_yaw * rng.standard_normal()
            else:
                meas.x = meas.x + config.noise_pos * rng.standard_normal(shape)[noise_part]
                meas.y = meas.y + config.noise_pos * rng.standard_normal(shape)[noise_part]
                meas.yaw = meas.yaw + config.noise_yaw * rng.standard_normal(shape)[noise_part]
        if len(groups) == 1 and groups[0][1] is None:
            cmd = groups[0][0].step(t, meas, ref)
            speed_cmd, yaw_rate_cmd = cmd.speed, cmd.yaw_rate
            if vector:
                ux, uy = cmd.ux, cmd.uy
        else:
            assert n is not None   # the groups split n vehicles
            speed_cmd, yaw_rate_cmd = np.empty(n), np.empty(n)
            if vector:
                ux, uy = np.empty(n), np.empty(n)
            for tracker, sl in groups:
                cmd = tracker.step(t, _take(meas, sl), _take(ref, sl))
                speed_cmd[sl], yaw_rate_cmd[sl] = cmd.speed, cmd.yaw_rate
                if vector:
                    ux[sl], uy[sl] = cmd.ux, cmd.uy
        if k:
            tv_speed = tv_speed + abs(speed_cmd - last_speed)
            tv_yaw = tv_yaw + abs(yaw_rate_cmd - last_yaw_rate)
        last_speed, last_yaw_rate = speed_cmd, yaw_rate_cmd
        if at_limit_from is not None and step_index >= half:
            at_limit = at_limit + (abs(yaw_rate_cmd) >= at_limit_from)
            at_limit_steps += 1

        for j in range(substeps):
            if j:
                ref = reference.sample(t + j * h)
            ex, ey = ref.x - state.x, ref.y - state.y
            err2 = ex * ex + ey * ey
            cost = cost + err2 * h
            if step_index >= half:
                steady = steady + err2
            if trace_stride is not None and step_index % trace_stride == 0:
                _record(trace, t + j * h, state, ref, speed_cmd, yaw_rate_cmd, meas, groups, n)
            state = (model.step_vector(state, ux, uy, h) if vector
                     else model.step(state, speed_cmd, yaw_rate_cmd, h))
            step_index += 1
        if progress is not None and (k % report_every == 0 or k == n_control - 1):
            progress((k + 1) / n_control)

    steady_count = step_index - half
    result = SimResult(f_cost=np.sqrt(cost) if n is not None else math.sqrt(cost),
                       steady_rms=(np.sqrt(steady / steady_count) if n is not None
                                   else math.sqrt(steady / steady_count)),
                       speed_tv=tv_speed / config.duration, yaw_rate_tv=tv_yaw / config.duration,
                       yaw_at_limit=(at_limit / at_limit_steps if at_limit_steps else zero))
    if n is None:
        result.yaw_at_limit = float(result.yaw_at_limit)
    if trace:
        result.trace = {key: np.asarray(values) for key, values in trace.items()}
    return result


def _ops_finite(value: Num) -> bool:
    return bool(np.all(np.isfinite(value)))


def _record(trace: dict[str, list[np.ndarray]], t: float, state: RoverState, ref: Reference,
            speed_cmd: Num, yaw_rate_cmd: Num, meas: Measurement,
            groups: Sequence[tuple[Tracker, slice | None]], n: int | None) -> None:
    def put(key: str, value: Num) -> None:
        trace.setdefault(key, []).append(np.array(value, dtype=float, copy=True))

    put("t", t)
    put("x", state.x)
    put("y", state.y)
    put("yaw", state.yaw)
    put("v", state.v)
    put("omega", state.omega)
    put("x_ref", ref.x)
    put("y_ref", ref.y)
    put("v_cmd", speed_cmd)
    put("omega_cmd", yaw_rate_cmd)
    # Filtering errors e_f = measurement - estimate (Figure 9): 0 for a tracker that flies the
    # raw measurement, NaN before a tracker's first step.
    ef = {k: np.full(n if n is not None else (), np.nan) for k in ("ex", "ey", "eyaw")}
    for tracker, sl in groups:
        est = tracker.estimate
        if est is None:
            continue
        m = meas if sl is None else _take(meas, sl)
        idx = ... if sl is None else sl   # Ellipsis also indexes the 0-d array of one vehicle
        ef["ex"][idx] = m.x - est.x
        ef["ey"][idx] = m.y - est.y
        ef["eyaw"][idx] = (m.yaw - est.yaw + math.pi) % (2 * math.pi) - math.pi
    for key, value in ef.items():
        put(key, value)
