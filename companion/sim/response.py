"""The inner loops alone: speed and turn rate answering a sequence of setpoints, many models at once.

What identification fits and what the plant's tests check: given the setpoints an autopilot was
sent (speed ``v_ref``, turn rate ``omega_ref``, held between samples) this runs only the two
channels of :class:`companion.sim.plant.RoverModel` (delay -> clamp with both couplings -> rate
limit -> lag -> the overshoot of each), without the pose, for ``n`` parameter sets side by side (any :class:`RoverParams` field may
be an array of length ``n``). The same channel solution (:func:`companion.sim.actuator.channel`) and
delay line as the full model, so a fitted model is the model the simulations run.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from . import plant_lanes
from .actuator import lag_step
from .command_delay import CommandDelay, delay_steps
from .plant import RoverModel, RoverParams


def respond(params: RoverParams, t: ArrayLike, speed_cmd: ArrayLike,
            yaw_rate_cmd: ArrayLike, n: int, dt: float = 0.01,
            v0: float = 0.0, omega0: float = 0.0, compiled: bool = True
            ) -> tuple[np.ndarray, np.ndarray]:
    """Speed and turn rate at the times ``t`` (s, increasing) for ``n`` models.

    ``speed_cmd[k]`` / ``yaw_rate_cmd[k]`` is the setpoint given at ``t[k]`` and held until
    ``t[k+1]``. The channels are stepped on a ``dt`` grid from ``t[0]``; each sample is read at
    the grid point at or just before its time, and a setpoint is in force from the grid point
    at or just after its time (both to within 1e-9 of a step: float rounding of the times).
    Returns two arrays of shape ``(len(t), n)``. The step loop is compiled where numba is
    installed (:func:`companion.sim.plant_lanes.respond_series`: the same arithmetic per model;
    ``compiled=False`` steps numpy, the reference).
    """
    t = np.asarray(t, dtype=float)
    u_in = np.asarray(speed_cmd, dtype=float)
    w_in = np.asarray(yaw_rate_cmd, dtype=float)
    if not (t.shape == u_in.shape == w_in.shape) or t.ndim != 1 or len(t) < 2:
        raise ValueError("t, speed_cmd and yaw_rate_cmd must be 1-D and of one length >= 2")
    if np.any(np.diff(t) < 0):
        raise ValueError("t must not decrease")
    # the clamps and couplings (the channels are stepped here, not by the model's own step)
    model = RoverModel(params.with_(speed_delay=0.0, yaw_delay=0.0), n)
    p = params
    delay = CommandDelay(p.speed_delay, p.yaw_delay, n) if p.has_delay else None
    m = model._m
    steps = int(np.floor((t[-1] - t[0]) / dt)) + 1
    grid = t[0] + dt * np.arange(steps)
    # The setpoint in force at each step; a setpoint sent at a grid point's time (up to float
    # rounding of both: 0.02 + 0.02 + ... is not 0.06) is in force from that point, not one
    # step later, as each sample is read at its own grid point below.
    held = np.searchsorted(t, grid + 1e-9 * dt, side="right") - 1
    sample_step = np.minimum(((t - t[0]) / dt + 1e-9).astype(int), steps - 1)
    over, over_w = model.switches["overshoot"], model.switches["yaw_overshoot"]
    if compiled and plant_lanes.available():
        lags = delay_steps(p.speed_delay, p.yaw_delay, dt, n)
        v_out, w_out = plant_lanes.respond_series(p, n, model.switches, u_in, w_in, held, lags,
                                                  v0, omega0, dt, steps)
        return v_out[sample_step], w_out[sample_step]
    v = np.full(n, float(v0))
    x = v                               # the speed channel's output (v without overshoot)
    z = v
    w = np.full(n, float(omega0))
    xw = w                              # the turn-rate channel's output (omega without overshoot)
    zw = w
    v_out = np.empty((steps, n))
    w_out = np.empty((steps, n))
    for k in range(steps):
        v_out[k], w_out[k] = v, w
        u_k, w_k = u_in[held[k]], w_in[held[k]]
        if delay is not None:
            u_k, w_k = delay.push(u_k + np.zeros(n), w_k + np.zeros(n), dt)
        u_k, w_k, top_w = model.clamp_with_top(u_k, w_k, w, v)
        v, x, z = lag_step(m, x, z, u_k, p.w_c, p.max_accel, p.decel, dt, p.speed_overshoot,
                           p.speed_overshoot_s, over)
        w, xw, zw = lag_step(m, xw, zw, w_k, p.yaw_bandwidth, p.max_yaw_accel, p.yaw_decel, dt,
                             p.yaw_overshoot, p.yaw_overshoot_s, over_w, top_w)
    return v_out[sample_step], w_out[sample_step]
