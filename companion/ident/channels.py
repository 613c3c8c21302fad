"""One channel of :func:`companion.sim.response.respond` at a time: what the fit's search runs.

``respond`` steps both channels for every parameter set; a search over the turn-rate channel's
parameters needs only that channel, and one over the speed channel's needs the turn rate only
as it is (the fitted turn-rate model's), not per candidate. Stepping one channel halves the cost
of a search round. The clamps each step meets are computed for the whole series first (they read
only the other channel's given output), then :func:`companion.sim.lag_series.lag_series` runs the
step loop itself (compiled where numba is installed).

The model is respond's, step for step: the same grid (``dt`` from ``t[0]``, the setpoint in
force at each grid point, each sample read at the grid point at or just before it), a pure delay
of ``round(delay / dt)`` steps with zeros before the first setpoint (as
:class:`companion.sim.command_delay.CommandDelay`), the clamps with the couplings evaluated on the
other channel's output at the start of the step (as :meth:`RoverModel.clamp_command`: the speed
clamp on the turn rate, the turn-rate clamp on the speed, as the turning radius and the lateral-acceleration limit do), and the exact rate-limited lag of
:func:`companion.sim.actuator.channel`. Each channel takes the other's output on the grid as
given (the fit gives the turn-rate channel the measured speed, the speed channel the fitted
turn-rate model's output); given respond's own, each is respond's. ``tests/ident/test_identify.py``
holds the two to each other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..sim.lag_series import lag_series
from ..sim.plant import LAT_ACCEL_MIN_SPEED


@dataclass(frozen=True)
class Grid:
    """respond's time grid for one series: per grid step the setpoint index in force, and per
    sample its grid step."""

    steps: int
    held: np.ndarray
    sample_step: np.ndarray

    @classmethod
    def of(cls, t: np.ndarray, dt: float) -> Grid:
        steps = int(np.floor((t[-1] - t[0]) / dt)) + 1
        grid = t[0] + dt * np.arange(steps)
        held = np.searchsorted(t, grid + 1e-9 * dt, side="right") - 1     # as respond
        sample_step = np.minimum(((t - t[0]) / dt + 1e-9).astype(int), steps - 1)
        return cls(steps, held, sample_step)


def _delayed(commands: np.ndarray, delay, n: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The setpoints padded with zeros in front and each of ``n`` models' offset into them:
    model i's delayed setpoint at grid step k is ``padded[k + offset[i]]``."""
    lag = np.broadcast_to(np.rint(np.asarray(delay, dtype=float) / dt).astype(int), (n,))
    padded = np.concatenate([np.zeros(int(lag.max(initial=0))), commands])
    return padded, int(lag.max(initial=0)) - lag


def turn_rate(t: np.ndarray, yaw_rate_cmd: np.ndarray, n: int, dt: float, omega0: float,
              delay, bandwidth, max_rate, accel, decel, coupling=0.0,
              speed_grid: np.ndarray | None = None, max_speed=np.inf, turn_radius=0.0,
              lat_accel=np.inf, overshoot=0.0, overshoot_s=1.0) -> tuple[np.ndarray, np.ndarray]:
    """The turn rate of ``n`` models at the samples ``t``, and on the grid (shape (steps, n)).

    With ``coupling`` (``speed_turn_coupling``, c_w) the clamp shrinks with the speed on the
    grid ``speed_grid`` (one value per grid step, or one column per model):
    ``max_rate (1 - c_w min(1, |v| / max_speed))``; with ``turn_radius`` R (Ackermann) it is
    at most ``|v| / R`` and with ``lat_accel`` a at most ``a / max(|v|, 1 m/s)``, as
    :meth:`companion.sim.plant.RoverModel.clamp_command`; with ``overshoot`` (the rate loop's
    two time scales, may be negative) the channel's output passes
    :func:`companion.sim.actuator.overshoot_step` and is capped at the clamp, as respond's."""
    g = Grid.of(t, dt)
    padded, offset = _delayed(np.asarray(yaw_rate_cmd, dtype=float)[g.held], delay, n, dt)
    coupled = bool(np.any(np.asarray(coupling) > 0))
    curved = bool(np.any(np.asarray(turn_radius) > 0))
    lateral = bool(np.any(np.isfinite(lat_accel)))
    top = np.broadcast_to(np.asarray(max_rate, dtype=float), (n,))[None, :]
    if coupled or curved or lateral:
        if speed_grid is None or len(speed_grid) < g.steps:
            raise ValueError("a coupled turn-rate channel needs the speed on every grid step")
        # The clamp per grid step, before the loop: it does not depend on the turn rate.
        speed = np.abs(speed_grid[:g.steps])
        if speed.ndim == 1:
            speed = speed[:, None]
        top = top + np.zeros((g.steps, n))
        if coupled:
            top = top * (1.0 - coupling * np.minimum(speed / max_speed, 1.0))
        if curved:
            radius = np.asarray(turn_radius, dtype=float)
            top = np.minimum(top, np.where(radius > 0, speed / np.where(radius > 0, radius, 1.0),
                                           np.inf))
        if lateral:
            top = np.minimum(top, lat_accel / np.maximum(speed, LAT_ACCEL_MIN_SPEED))
    out = lag_series(padded, offset, top, g.steps, float(omega0), bandwidth, accel, decel, dt,
                     overshoot, overshoot_s, capped=True)
    return out[g.sample_step], out


def speed(t: np.ndarray, speed_cmd: np.ndarray, omega_grid: np.ndarray, n: int, dt: float,
          v0: float, delay, bandwidth, max_speed, accel, decel, coupling,
          max_yaw_rate, overshoot=0.0, overshoot_s=1.0) -> np.ndarray:
    """The speed of ``n`` models at the samples ``t``, given the turn rate on the grid (one
    column, the fitted turn-rate model's, or one per model), which the coupling (the speed
    clamp lost while turning) reads; with ``overshoot`` the channel's output passes
    :func:`companion.sim.actuator.overshoot_step` (the coupling reads the speed itself)."""
    g = Grid.of(t, dt)
    padded, offset = _delayed(np.asarray(speed_cmd, dtype=float)[g.held], delay, n, dt)
    top = np.broadcast_to(np.asarray(max_speed, dtype=float), (n,))[None, :]
    if bool(np.any(np.asarray(coupling) > 0)):
        # The clamp per grid step, before the loop: it reads the given turn rate only.
        omega = omega_grid if omega_grid.ndim == 2 else omega_grid[:, None]
        top = top * (1.0 - coupling * np.minimum(np.abs(omega[:g.steps]) / max_yaw_rate, 1.0))
    out = lag_series(padded, offset, top, g.steps, float(v0), bandwidth, accel, decel, dt,
                     overshoot, overshoot_s)
    return out[g.sample_step]
