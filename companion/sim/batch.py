"""Closed-loop simulation of one rover (floats) or thousands at once (numpy arrays).

The plant (:mod:`companion.sim.plant`) is integrated with RK4 on a fine fixed step (1 ms or finer);
the trackers run at their own rate (1 kHz down to 10 Hz or less) on the sampled pose, and their
command is held (zero-order hold) until the next control step, as on a real autopilot link.
The very same tracker objects run here and in the live MAVLink loop (a vehicle model with
PX4's course loop takes the command's u_p, :meth:`~companion.sim.plant.RoverModel.step_command`);
``n=None`` simulates one vehicle on Python floats, ``n=k`` simulates k vehicles on arrays, each
tracker owning a slice.

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
    ``progress(fraction)`` is called about a hundred times. The model takes each command as its
    vehicle does (:meth:`companion.sim.plant.RoverModel.step_command`: u_p where it has PX4's
    course loop, else speed and turn rate).
    """
    groups: list[tuple[Tracker, slice | None]] = (
        list(trackers) if isinstance(trackers, Sequence) else [(trackers, None)])
    for tracker, _ in groups:
        tracker.reset()
    model = batch_model(params, n)
    zero = 0.0 if n is None else np.zeros(n)
    x0, y0, yaw0 = config.start
    state = RoverState(x0 + zero, y0 + zero, yaw0 + zero, zero, zero)
    noise = _Noise(config, n)
    times, substeps_after, h = config.schedule()
    n_control = len(times)
    tally = _Tally(config, params, zero, sum(substeps_after) // 2)
    trace_stride = None if config.trace_every is None else max(1, round(config.trace_every / h))
    trace: dict[str, list] = {}
    report_every = max(1, n_control // 100)
    cost = steady = zero
    step_index, half = 0, tally.half
    for k in range(n_control):
        t = times[k]
        ref = reference.sample(t)
        meas = noise.add(model.measure(state))
        speed_cmd, yaw_rate_cmd, vector = _commands(groups, t, meas, ref, n)
        tally.command(k, speed_cmd, yaw_rate_cmd, step_index)
        for j in range(substeps_after[k]):
            if j:
                ref = reference.sample(t + j * h)
            ex, ey = ref.x - state.x, ref.y - state.y
            err2 = ex * ex + ey * ey
            cost = cost + err2 * h
            if step_index >= half:
                steady = steady + err2
            if trace_stride is not None and step_index % trace_stride == 0:
                _record(trace, t + j * h, state, ref, speed_cmd, yaw_rate_cmd, meas, groups, n)
            state = model.step_command(state, speed_cmd, yaw_rate_cmd, h, vector)
            step_index += 1
        if progress is not None and (k % report_every == 0 or k == n_control - 1):
            progress((k + 1) / n_control)
    result = tally.result(cost, steady, step_index - half, n)
    if trace:
        result.trace = {key: np.asarray(values) for key, values in trace.items()}
    return result


class _Noise:
    """White noise on the measured pose (SimConfig.noise_pos / noise_yaw, seeded); with a
    ``noise_slice`` each vehicle draws the whole batch's noise and keeps its own."""

    def __init__(self, config: SimConfig, n: int | None):
        self.rng = np.random.default_rng(config.seed)
        self.pos, self.yaw = config.noise_pos, config.noise_yaw
        self.on = self.pos > 0 or self.yaw > 0
        self.shape: int | None = n
        self.part = slice(None)
        if config.noise_slice is not None and n is not None:
            total, first = config.noise_slice
            self.shape, self.part = total, slice(first, first + n)

    def add(self, meas: Measurement) -> Measurement:
        if not self.on:
            return meas
        rng, shape = self.rng, self.shape
        if shape is None:
            meas.x = meas.x + self.pos * rng.standard_normal()
            meas.y = meas.y + self.pos * rng.standard_normal()
            meas.yaw = meas.yaw + self.yaw * rng.standard_normal()
        else:
            meas.x = meas.x + self.pos * rng.standard_normal(shape)[self.part]
            meas.y = meas.y + self.pos * rng.standard_normal(shape)[self.part]
            meas.yaw = meas.yaw + self.yaw * rng.standard_normal(shape)[self.part]
        return meas


def _commands(groups: Sequence[tuple[Tracker, slice | None]], t: float, meas: Measurement,
              ref: Reference, n: int | None) -> tuple[Num, Num, tuple[Num, Num]]:
    """Every tracker's step: (speed, turn rate, u_p) for all the vehicles."""
    if len(groups) == 1 and groups[0][1] is None:
        cmd = groups[0][0].step(t, meas, ref)
        return cmd.speed, cmd.yaw_rate, (cmd.ux, cmd.uy)
    assert n is not None   # the groups split n vehicles
    speed, yaw_rate, ux, uy = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    for tracker, sl in groups:
        cmd = tracker.step(t, _take(meas, sl), _take(ref, sl))
        speed[sl], yaw_rate[sl], ux[sl], uy[sl] = cmd.speed, cmd.yaw_rate, cmd.ux, cmd.uy
    return speed, yaw_rate, (ux, uy)


class _Tally:
    """What the commands show (their total variation, the share at the turn-rate limit) and the
    result made of it and the integrated errors."""

    def __init__(self, config: SimConfig, params: RoverParams, zero: Num, half: int):
        self.duration, self.half, self.zero = config.duration, half, zero
        limit = config.yaw_rate_limit if config.yaw_rate_limit is not None else params.max_yaw_rate
        self.at_limit_from = (0.98 * np.asarray(limit, dtype=float) if _ops_finite(limit)
                              else None)
        self.tv_speed = self.tv_yaw = self.at_limit = zero
        self.at_limit_steps = 0
        self.last_speed = self.last_yaw_rate = zero   # the previous step's commands

    def command(self, k: int, speed: Num, yaw_rate: Num, step_index: int) -> None:
        if k:
            self.tv_speed = self.tv_speed + abs(speed - self.last_speed)
            self.tv_yaw = self.tv_yaw + abs(yaw_rate - self.last_yaw_rate)
        self.last_speed, self.last_yaw_rate = speed, yaw_rate
        if self.at_limit_from is not None and step_index >= self.half:
            self.at_limit = self.at_limit + (abs(yaw_rate) >= self.at_limit_from)
            self.at_limit_steps += 1

    def result(self, cost: Num, steady: Num, steady_count: int, n: int | None) -> SimResult:
        root = np.sqrt if n is not None else math.sqrt
        result = SimResult(f_cost=root(cost), steady_rms=root(steady / steady_count),
                           speed_tv=self.tv_speed / self.duration,
                           yaw_rate_tv=self.tv_yaw / self.duration,
                           yaw_at_limit=(self.at_limit / self.at_limit_steps
                                         if self.at_limit_steps else self.zero))
        if n is None:
            result.yaw_at_limit = float(result.yaw_at_limit)
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
