"""The plant's step for many vehicles as compiled loops: batch simulation's and identification's.

:class:`LaneStepper` advances every vehicle of a :class:`companion.sim.plant.RoverModel` built
on arrays by one step: PX4's course loop (``step_vector``), the commands' pure delay
(:class:`companion.sim.command_delay.CommandDelay`'s ring buffers), ``clamp_command``, the
rate-limited channels with their overshoots (``_channel``, ``overshoot_step``,
``overshoot_integral``) and Simpson's rule for x and y (``_simpson``): the same operations in
the same order, per vehicle on floats; :class:`LaneModel` is a ``RoverModel`` whose steps go
there, and :func:`batch_model` the model batch simulation builds (a ``LaneModel`` where numba
compiled the loop, else the numpy ``RoverModel``). :func:`respond_series` is
:func:`companion.sim.response.respond`'s loop (the two channels alone over a whole setpoint
series, what a fit's RMS and its plots run) the same way.

Stepped by numpy, a batch step costs about 150 array operations whatever the number of vehicles
is, which was most of a robust evaluation, and respond on one model is all overhead (measured:
docs/design/vehicle-model.md). Compiled by numba (when it is installed) a step is one pass over
the vehicles. Both compute the same numbers (to rounding:
``tests/sim/test_plant_lanes.py``); ``RoverModel`` itself and ``respond(..., compiled=False)``
are numpy, the reference, and know nothing of this module. The paper's exact linear step (no limits) is not
compiled: nothing tunes on it.

Pure: arrays in, arrays out (numba's cache of the compiled loops aside).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ..core.ops import TAU
from ..core.signals import Num
from .actuator import overshoot_target
from .command_delay import CommandDelay
from .plant import LAT_ACCEL_MIN_SPEED, RoverModel, RoverParams, RoverState

_compiled: Callable[..., None] | None = None     # _loop, compiled (when numba is here)
_respond_compiled: Callable[..., None] | None = None     # _respond_loop, likewise

# The parameters the loop reads, in its argument order (RoverParams' fields and properties).
PARAMS = ("d_cen", "w_c", "yaw_bandwidth", "max_speed", "max_yaw_rate", "max_accel", "decel",
          "max_yaw_accel", "yaw_decel", "turn_speed_coupling", "speed_turn_coupling",
          "course_gain", "min_turn_radius", "max_lat_accel", "speed_overshoot",
          "speed_overshoot_s", "yaw_overshoot", "yaw_overshoot_s")
# RoverModel's switches, in the loop's order: each on when any vehicle needs it (as in numpy)
SWITCHES = ("coupled", "turn_coupled", "curvature", "lateral", "overshoot", "yaw_overshoot")


def available() -> bool:
    """True where numba compiled the loop (x86-64 and 64-bit ARM: pyproject installs it)."""
    return _compiled is not None


def batch_model(params: RoverParams, n: int | None) -> RoverModel:
    """The model batch simulation steps: compiled on many rate-limited vehicles where numba is
    here, the numpy reference otherwise (one vehicle, the paper's exact step, no numba)."""
    if n is None or params.is_paper or not available():
        return RoverModel(params, n)
    return LaneModel(params, n)


class LaneModel(RoverModel):
    """:class:`RoverModel` on ``n`` vehicles whose :meth:`step` and :meth:`step_vector` are one
    compiled pass over them (:class:`LaneStepper`); everything else is RoverModel's own."""

    def __init__(self, params: RoverParams, n: int, loop: Callable[..., None] | None = None):
        super().__init__(params, n)
        self.lanes = LaneStepper(params, n, self.switches, self.delay, loop)

    def step_vector(self, s: RoverState, ux: Num, uy: Num, dt: float) -> RoverState:
        return self._lane_step(s, ux, uy, dt, vector=True)

    def step(self, s: RoverState, speed_cmd: Num, yaw_rate_cmd: Num, dt: float) -> RoverState:
        return self._lane_step(s, speed_cmd, yaw_rate_cmd, dt, vector=False)

    def _lane_step(self, s: RoverState, a: Num, b: Num, dt: float, vector: bool) -> RoverState:
        out = self.lanes.step(s, a, b, dt, vector)
        state = RoverState(out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7])
        self._trig_yaw, self._trig_cs = state.yaw, (out[8], out[9])    # as RoverModel._trig
        return state


class LaneStepper:
    """The vehicles of one model on arrays, stepped by the compiled loop (:class:`LaneModel`'s
    steps hand their arrays here and build the new state from the rows)."""

    def __init__(self, params: RoverParams, n: int, switches: dict[str, bool],
                 delay: CommandDelay | None, loop: Callable[..., None] | None = None):
        self.n = n
        self.delay = delay
        chosen = loop or _compiled
        assert chosen is not None, "a stepper is built only where numba compiled the loop"
        self._loop: Callable[..., None] = chosen
        self._params = param_rows(params, n)
        self._switches = [switches[name] for name in SWITCHES]
        # an undelayed model's stand-ins for the ring buffers (never read)
        self._no_ring, self._no_lags = np.zeros((2, 1, 1)), np.zeros((2, 1), dtype=np.int64)
        self._last: np.ndarray | None = None     # the last step's rows (the state it returned)
        self._decays: tuple[float, np.ndarray] | None = None      # (h, _decays for it)

    def step(self, s: RoverState, a: Num, b: Num, h: float, vector: bool) -> np.ndarray:
        """(a, b): (speed, turn rate) or, ``vector``, PX4's (u_x, u_y). Rows of the result: x,
        y, yaw, v, omega, v_slow, w_slow, w_lag, and the cosine and sine of the new yaw."""
        n, delay = self.n, self.delay
        if delay is not None:
            k = delay.advance(h)              # CommandDelay.push: the loop writes slot k
            ring, lags = delay.ring, delay.lags
        else:
            k, ring, lags = 0, self._no_ring, self._no_lags
        last = self._last
        fields = (s.x, s.y, s.yaw, s.v, s.omega, s.v_slow, s.w_slow, s.w_lag)
        # the state this stepper returned last (the usual case) is its rows, cos and sin included
        state = last if last is not None and all(
            f is last[i] for i, f in enumerate(fields)) else None
        if state is None:
            state = np.empty((10, n))
            for i, f in enumerate(fields[:7]):
                state[i] = f
            # no lag output yet: the one the turn rate tells
            g = self._params[PARAMS.index("yaw_overshoot")]
            state[7] = overshoot_target(state[4], state[6], g) if s.w_lag is None else s.w_lag
        h = float(h)
        if self._decays is None or self._decays[0] != h:
            decays = np.empty((8, n))
            _decays(self._params, h, decays)
            self._decays = (h, decays)
        out = np.empty((10, n))
        self._loop(vector, delay is not None, state is last, *self._switches, _lanes(a, n),
                   _lanes(b, n), state, self._params, self._decays[1], ring, lags, k, h, out)
        self._last = out
        return out


def _lanes(value: Num, n: int) -> np.ndarray:
    """One float64 per vehicle, contiguous (what the compiled loop takes)."""
    if type(value) is np.ndarray and value.dtype == np.float64 and value.shape == (n,) \
            and value.flags.c_contiguous:
        return value
    return np.ascontiguousarray(np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)))


def _nan_min(a: float, b: float) -> float:
    """numpy's minimum: NaN if either is (a diverged vehicle stays diverged)."""
    if a != a or b != b:
        return math.nan
    return a if a < b else b


def _nan_max(a: float, b: float) -> float:
    if a != a or b != b:
        return math.nan
    return a if a > b else b


def _clamp(speed_cmd: float, yaw_cmd: float, v: float, omega: float, max_speed: float,
           max_yaw_rate: float, tsc: float, stc: float, min_radius: float, lat_accel: float,
           coupled: bool, turn_coupled: bool, curvature: bool, lateral: bool
           ) -> tuple[float, float, float]:
    """``RoverModel.clamp_command``: the commands clamped to the ranges the state (v, omega)
    leaves them, and the turn rate's range (``RoverModel.tops``: what caps an overshoot)."""
    top = max_speed
    if coupled:
        top = top * (1.0 - tsc * _nan_min(abs(omega) / max_yaw_rate, 1.0))
    top_w = max_yaw_rate
    if turn_coupled:
        top_w = top_w * (1.0 - stc * _nan_min(abs(v) / max_speed, 1.0))
    if curvature:
        top_w = _nan_min(top_w, abs(v) / (min_radius if min_radius > 0 else 1e-12))
    if lateral:
        top_w = _nan_min(top_w, lat_accel / _nan_max(abs(v), LAT_ACCEL_MIN_SPEED))
    return (_nan_min(_nan_max(speed_cmd, -top), top),
            _nan_min(_nan_max(yaw_cmd, -top_w), top_w), top_w)


def _channel(x0: float, u: float, b: float, up: float, down: float, t: float,
             whole: float) -> tuple[float, float]:
    """``actuator.channel`` at one time ``t``: (x(t), its integral from 0). ``whole`` is
    exp(-b t), the decay when no ramp is needed (the usual case: one exp less)."""
    e0 = u - x0
    limit = down if e0 * x0 < 0 else up
    knee = limit / b
    t1 = _nan_max(abs(e0) / limit - 1.0 / b, 0.0)
    e1 = _nan_min(_nan_max(e0, -knee), knee)
    ramp = (-limit if e0 < 0 else limit) if t1 > 0 else 0.0
    tr = _nan_min(t, t1)
    te = t - tr
    decay = whole if tr == 0.0 else math.exp(-b * te)
    x = u - e1 * decay if te > 0 else x0 + ramp * tr
    integral = x0 * tr + 0.5 * ramp * tr * tr + (u * te - e1 * (1.0 - decay) / b)
    return x, integral


def _overshoot(x0: float, x1: float, z0: float, g: float, keep: float) -> tuple[float, float]:
    """``actuator.overshoot_step`` with ``keep`` = exp(-t / tau): (output, z)."""
    z1 = z0 + (1.0 - keep) * (0.5 * (x0 + x1) - z0)
    return (1.0 + g) * x1 - g * z1, z1


def _overshoot_integral(x0: float, x1: float, x_integral: float, z0: float, g: float,
                        tau: float, t: float, keep: float) -> float:
    """``actuator.overshoot_integral`` with ``keep`` = exp(-t / tau)."""
    xm = 0.5 * (x0 + x1)
    z_integral = xm * t - (xm - z0) * tau * (1.0 - keep)
    return (1.0 + g) * x_integral - g * z_integral


def _decays(p: Any, h: float, out: Any) -> None:   # pragma: no cover - compiled
    """The exponentials a step of ``h`` needs that do not change from step to step, rows:
    exp(-b t) of the speed and turn-rate channels and exp(-t / tau) of their overshoots, each
    at t = h / 2 and h (``p``: rows of :data:`PARAMS`)."""
    for i in range(out.shape[1]):
        for j, t in enumerate((0.5 * h, h)):
            out[j, i] = math.exp(-p[1, i] * t)
            out[2 + j, i] = math.exp(-p[2, i] * t)
            out[4 + j, i] = math.exp(-t / p[15, i])
            out[6 + j, i] = math.exp(-t / p[17, i])


def _loop(vector: bool, delayed: bool, trig: bool, coupled: bool, turn_coupled: bool,
          curvature: bool, lateral: bool, overshoot: bool, yaw_overshoot: bool,
          a: Any, b: Any, state: Any, p: Any, decays: Any, ring: Any, lags: Any, k: int,
          h: float, out: Any) -> None:   # pragma: no cover - compiled; as Python: test_plant_lanes
    """One step of every vehicle i: ``RoverModel.step_vector`` / ``step`` then ``_step_limited``
    as numpy runs them, per vehicle on floats. ``state`` and ``out`` rows: x, y, yaw, v, omega,
    v_slow, w_slow, w_lag, cos(yaw), sin(yaw) (``trig``: the state's are there, else computed). ``p``
    rows: :data:`PARAMS`; ``decays``: :func:`_decays`'s for ``h``; ``ring`` and ``lags``:
    CommandDelay's (``delayed``)."""
    for i in range(out.shape[1]):
        speed_cmd, yaw_cmd = _command(vector, delayed, a[i], b[i], state[2, i], p[11, i], ring,
                                      lags, k, i)
        u, w, top_w = _clamp(speed_cmd, yaw_cmd, state[3, i], state[4, i], p[3, i], p[4, i],
                             p[9, i], p[10, i], p[12, i], p[13, i], coupled, turn_coupled,
                             curvature, lateral)
        v_mid, v_end, z_end = _speed_channel(state[3, i], state[5, i], u, p[1, i], p[5, i],
                                             p[6, i], p[14, i], overshoot, h, decays, i)
        w_mid, w_end, i_mid, i_end, wz_end, x_end = _turn_channel(
            state[4, i], state[6, i], state[7, i], w, top_w, p[2, i], p[7, i], p[8, i],
            p[16, i], p[17, i], yaw_overshoot, h, decays, i)
        _simpson(state, i, trig, p[0, i], v_mid, v_end, w_mid, w_end, i_mid, i_end, h, out)
        out[5, i] = z_end
        out[6, i] = wz_end
        out[7, i] = x_end


def _command(vector: bool, delayed: bool, a: float, b: float, yaw0: float, course_gain: float,
             ring: Any, lags: Any, k: int, i: int
             ) -> tuple[float, float]:   # pragma: no cover - compiled; as Python: test_plant_lanes
    """Vehicle i's (speed, turn rate) commands out of the delay: ``step_vector``'s course loop on
    PX4's u_p = (a, b) (else (a, b) are the commands), then ``CommandDelay.push``."""
    if vector:                                  # PX4's course loop on u_p
        angle = math.atan2(b, a) - yaw0
        course_err = angle - TAU * math.ceil((angle - math.pi) * (1.0 / TAU))
        speed_cmd = math.hypot(a, b)
        yaw_cmd = course_gain * course_err
    else:
        speed_cmd, yaw_cmd = a, b
    if delayed:                                 # CommandDelay.push
        size = ring.shape[1]
        ring[0, k % size, i] = speed_cmd
        ring[1, k % size, i] = yaw_cmd
        speed_cmd = ring[0, (k - lags[0, i]) % size, i]
        yaw_cmd = ring[1, (k - lags[1, i]) % size, i]
    return speed_cmd, yaw_cmd


def _speed_channel(v0: float, v_slow: float, u: float, w_c: float, accel: float, decel: float,
                   g_v: float, overshoot: bool, h: float, decays: Any, i: int
                   ) -> tuple[float, float, float]:   # pragma: no cover - compiled
    """``_step_limited``'s speed channel (and its overshoot) of vehicle i: (v at h/2, at h, z
    at h); ``decays``: :func:`_decays`'s rows."""
    z_end = v_slow
    vx0 = v0
    if overshoot:
        vx0 = (v0 + g_v * v_slow) / (1.0 + g_v)
    v_mid = _channel(vx0, u, w_c, accel, decel, 0.5 * h, decays[0, i])[0]
    v_end = _channel(vx0, u, w_c, accel, decel, h, decays[1, i])[0]
    if overshoot:
        v_mid = _overshoot(vx0, v_mid, v_slow, g_v, decays[4, i])[0]
        v_end, z_end = _overshoot(vx0, v_end, v_slow, g_v, decays[5, i])
    return v_mid, v_end, z_end


def _turn_channel(w0: float, w_slow: float, w_lag: float, w: float, top_w: float,
                  w_c_yaw: float, yaw_accel: float, yaw_decel: float, g_w: float, tau_w: float,
                  yaw_overshoot: bool, h: float, decays: Any, i: int
                  ) -> tuple[float, float, float, float, float, float]:   # pragma: no cover
    """``_step_limited``'s turn-rate channel (and its two time scales) of vehicle i and the
    heading it integrates: (omega at h/2, at h, the heading's change to each, z at h, the lag's x at h)."""
    if not yaw_overshoot:
        w_mid, i_mid = _channel(w0, w, w_c_yaw, yaw_accel, yaw_decel, 0.5 * h, decays[2, i])
        w_end, i_end = _channel(w0, w, w_c_yaw, yaw_accel, yaw_decel, h, decays[3, i])
        return w_mid, w_end, i_mid, i_end, w_slow, w_lag
    x0 = w_lag
    x_mid, ix_mid = _channel(x0, w, w_c_yaw, yaw_accel, yaw_decel, 0.5 * h, decays[2, i])
    x_end, ix_end = _channel(x0, w, w_c_yaw, yaw_accel, yaw_decel, h, decays[3, i])
    w_mid = _overshoot(x0, x_mid, w_slow, g_w, decays[6, i])[0]
    w_end, wz_end = _overshoot(x0, x_end, w_slow, g_w, decays[7, i])
    i_mid = _overshoot_integral(x0, x_mid, ix_mid, w_slow, g_w, tau_w, 0.5 * h, decays[6, i])
    i_end = _overshoot_integral(x0, x_end, ix_end, w_slow, g_w, tau_w, h, decays[7, i])
    if g_w != 0.0:                          # actuator.turn_rate_cap
        c_mid = _nan_min(_nan_max(w_mid, -top_w), top_w)
        c_end = _nan_min(_nan_max(w_end, -top_w), top_w)
        if c_mid != w_mid or c_end != w_end:
            i_mid = h / 24.0 * (5.0 * w0 + 8.0 * c_mid - c_end)
            i_end = h / 6.0 * (w0 + 4.0 * c_mid + c_end)
            w_mid, w_end = c_mid, c_end
    return w_mid, w_end, i_mid, i_end, wz_end, x_end


def _simpson(state: Any, i: int, trig: bool, d_cen: float, v_mid: float, v_end: float,
             w_mid: float, w_end: float, i_mid: float, i_end: float, h: float,
             out: Any) -> None:   # pragma: no cover - compiled; as Python: test_plant_lanes
    """``RoverModel._simpson`` for vehicle i (column i of ``state`` and ``out``): x and y
    from the heading, speed and turn rate at the start, middle and end; out's x, y, yaw, v,
    omega, cos(yaw) and sin(yaw) rows."""
    x, y, yaw0, v0, w0 = state[0, i], state[1, i], state[2, i], state[3, i], state[4, i]
    yaw_mid, yaw_end = yaw0 + i_mid, yaw0 + i_end
    if trig:
        c0, s0 = state[8, i], state[9, i]
    else:
        c0, s0 = math.cos(yaw0), math.sin(yaw0)
    c1, s1 = math.cos(yaw_mid), math.sin(yaw_mid)
    c2, s2 = math.cos(yaw_end), math.sin(yaw_end)
    lat0, lat1, lat2 = d_cen * w0, d_cen * w_mid, d_cen * w_end
    h6 = h / 6.0
    out[0, i] = x + h6 * ((v0 * c0 - lat0 * s0) + 4.0 * (v_mid * c1 - lat1 * s1)
                          + (v_end * c2 - lat2 * s2))
    out[1, i] = y + h6 * ((v0 * s0 + lat0 * c0) + 4.0 * (v_mid * s1 + lat1 * c1)
                          + (v_end * s2 + lat2 * c2))
    out[2, i] = yaw_end
    out[3, i] = v_end
    out[4, i] = w_end
    out[8, i] = c2
    out[9, i] = s2


def _lag_step(x: float, z: float, u: float, b: float, up: float, down: float, dt: float,
              whole: float, g: float, keep: float, over: bool, cap: float
              ) -> tuple[float, float, float]:
    """``actuator.lag_step``: (what is measured, the channel's output x, the overshoot's z);
    ``cap`` inf: none."""
    x1 = _channel(x, u, b, up, down, dt, whole)[0]
    if not over:
        return x1, x1, z
    y, z1 = _overshoot(x, x1, z, g, keep)
    if g != 0.0:
        y = _nan_min(_nan_max(y, -cap), cap)
    return y, x1, z1


def _respond_loop(u_cmd: Any, w_cmd: Any, held: Any, lags: Any, p: Any, coupled: bool,
                  turn_coupled: bool, curvature: bool, lateral: bool, over: bool, over_w: bool,
                  v0: float, w0: float, dt: float, v_out: Any, w_out: Any
                  ) -> None:   # pragma: no cover - compiled; as Python: test_plant_lanes
    """``companion.sim.response.respond``'s step loop per model on floats: the delayed setpoint
    in force (``u_cmd[held[k - lag]]``, zero before the first), ``clamp_command`` on the
    channels' outputs, then ``lag_step`` for each channel. ``p`` rows: :data:`PARAMS`;
    ``lags`` [channel, model]: delays in steps."""
    steps, n = v_out.shape
    for i in range(n):
        whole_v, whole_w = math.exp(-p[1, i] * dt), math.exp(-p[2, i] * dt)
        keep_v, keep_w = math.exp(-dt / p[15, i]), math.exp(-dt / p[17, i])
        v = x = z = v0
        w = xw = zw = w0
        for k in range(steps):
            v_out[k, i] = v
            w_out[k, i] = w
            ku, kw = k - lags[0, i], k - lags[1, i]
            u, r, top_w = _clamp(u_cmd[held[ku]] if ku >= 0 else 0.0,
                          w_cmd[held[kw]] if kw >= 0 else 0.0, v, w, p[3, i], p[4, i],
                          p[9, i], p[10, i], p[12, i], p[13, i], coupled, turn_coupled,
                          curvature, lateral)
            v, x, z = _lag_step(x, z, u, p[1, i], p[5, i], p[6, i], dt, whole_v, p[14, i],
                                keep_v, over, math.inf)
            w, xw, zw = _lag_step(xw, zw, r, p[2, i], p[7, i], p[8, i], dt, whole_w, p[16, i],
                                  keep_w, over_w, top_w)


def respond_series(params: RoverParams, n: int, switches: dict[str, bool],
                   u_cmd: np.ndarray, w_cmd: np.ndarray, held: np.ndarray, lags: np.ndarray,
                   v0: float, w0: float, dt: float, steps: int,
                   loop: Callable[..., None] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Speed and turn rate of ``n`` models on ``steps`` grid steps (respond's, compiled)."""
    chosen = loop or _respond_compiled
    assert chosen is not None, "respond compiles only where numba is installed"
    v_out, w_out = np.empty((steps, n)), np.empty((steps, n))
    chosen(np.ascontiguousarray(u_cmd, dtype=np.float64),
           np.ascontiguousarray(w_cmd, dtype=np.float64),
           np.ascontiguousarray(held, dtype=np.int64), np.ascontiguousarray(lags, dtype=np.int64),
           param_rows(params, n), *(switches[name] for name in SWITCHES), float(v0), float(w0), float(dt), v_out, w_out)
    return v_out, w_out


def param_rows(params: RoverParams, n: int) -> np.ndarray:
    """:data:`PARAMS` of ``params`` as rows of ``n`` floats (what the compiled loops read)."""
    return np.stack([np.broadcast_to(np.asarray(getattr(params, name), dtype=np.float64), (n,))
                     for name in PARAMS])


try:                                     # an optional accelerator: the numpy path is complete
    import numba
except ImportError:                      # pragma: no cover - platforms without numba's wheels
    pass
else:
    def _jit(function: Callable[..., Any]) -> Any:
        # error_model="numpy": a division by zero gives inf or NaN, as in numpy, not an error
        try:
            return numba.njit(cache=True, nogil=True, error_model="numpy")(function)
        except RuntimeError:             # pragma: no cover - "no locator available": read-only
            return numba.njit(nogil=True, error_model="numpy")(function)

    # the helpers first: the loop calls them by their global names
    _nan_min, _nan_max = _jit(_nan_min), _jit(_nan_max)
    _clamp = _jit(_clamp)
    _channel, _overshoot, _overshoot_integral = (
        _jit(_channel), _jit(_overshoot), _jit(_overshoot_integral))
    _decays = _jit(_decays)
    _command, _speed_channel, _turn_channel = (
        _jit(_command), _jit(_speed_channel), _jit(_turn_channel))
    _simpson = _jit(_simpson)
    _lag_step = _jit(_lag_step)
    _compiled = _jit(_loop)
    _respond_compiled = _jit(_respond_loop)
