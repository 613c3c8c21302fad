"""One channel of :func:`companion.sim.response.respond` at a time: what the fit's search runs.

``respond`` steps both channels for every parameter set; a search over the turn-rate channel's
parameters needs only that channel, and one over the speed channel's needs the turn rate only
as it is (the fitted turn-rate model's), not per candidate. Stepping one channel halves the cost
of a search round, whose cost is the Python step loop, not the population.

The model is respond's, step for step: the same grid (``dt`` from ``t[0]``, the setpoint in
force at each grid point, each sample read at the grid point at or just before it), a pure delay
of ``round(delay / dt)`` steps with zeros before the first setpoint (as
:class:`companion.sim.plant.CommandDelay`), the clamp with the coupling evaluated on the turn
rate at the start of the step (as :meth:`RoverModel.clamp_command`), and the exact
rate-limited lag of :func:`companion.sim.plant._channel`. ``tests/test_identify.py`` holds the
two to each other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import ops
from ..sim.plant import _channel


@dataclass(frozen=True)
class Grid:
    """respond's time grid for one series: per grid step the setpoint index in force, and per
    sample its grid step."""

    steps: int
    held: np.ndarray
    sample_step: np.ndarray

    @classmethod
    def of(cls, t: np.ndarray, dt: float) -> "Grid":
        steps = int(np.floor((t[-1] - t[0]) / dt)) + 1
        grid = t[0] + dt * np.arange(steps)
        held = np.searchsorted(t, grid, side="right") - 1
        sample_step = np.minimum(((t - t[0]) / dt + 1e-9).astype(int), steps - 1)
        return cls(steps, held, sample_step)


def _delayed(commands: np.ndarray, delay, n: int, dt: float):
    """Per grid step, the delayed setpoint of each of ``n`` models (a function of the step)."""
    lag = np.broadcast_to(np.rint(np.asarray(delay, dtype=float) / dt).astype(int), (n,))
    padded = np.concatenate([np.zeros(int(lag.max(initial=0))), commands])
    offset = int(lag.max(initial=0)) - lag
    return lambda k: padded[k + offset]


def turn_rate(t: np.ndarray, yaw_rate_cmd: np.ndarray, n: int, dt: float, omega0: float,
              delay, bandwidth, max_rate, accel, decel) -> tuple[np.ndarray, np.ndarray]:
    """The turn rate of ``n`` models at the samples ``t``, and on the grid (shape (steps, n))."""
    g = Grid.of(t, dt)
    m = ops.for_size(n)
    command = _delayed(np.asarray(yaw_rate_cmd, dtype=float)[g.held], delay, n, dt)
    w = np.full(n, float(omega0))
    out = np.empty((g.steps, n))
    for k in range(g.steps):
        out[k] = w
        u = m.clip(command(k), -max_rate, max_rate)
        _, w, _, _ = _channel(m, w, u, bandwidth, accel, decel, dt, both=False)
    return out[g.sample_step], out


def speed(t: np.ndarray, speed_cmd: np.ndarray, omega_grid: np.ndarray, n: int, dt: float,
          v0: float, delay, bandwidth, max_speed, accel, decel, coupling,
          max_yaw_rate) -> np.ndarray:
    """The speed of ``n`` models at the samples ``t``, given the turn rate on the grid (one
    column, the fitted turn-rate model's, or one per model)."""
    g = Grid.of(t, dt)
    m = ops.for_size(n)
    command = _delayed(np.asarray(speed_cmd, dtype=float)[g.held], delay, n, dt)
    coupled = bool(np.any(np.asarray(coupling) > 0))
    omega = omega_grid if omega_grid.ndim == 2 else omega_grid[:, None]
    v = np.full(n, float(v0))
    out = np.empty((g.steps, n))
    for k in range(g.steps):
        out[k] = v
        top = max_speed
        if coupled:
            top = top * (1.0 - coupling * m.minimum(abs(omega[k]) / max_yaw_rate, 1.0))
        u = m.clip(command(k), -top, top)
        _, v, _, _ = _channel(m, v, u, bandwidth, accel, decel, dt, both=False)
    return out[g.sample_step]
