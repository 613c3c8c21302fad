"""A channel's objective: the RMS of the simulated minus the measured output of one channel (turn
rate or speed) over a series, for a batch of parameter sets at once."""

from __future__ import annotations

import numpy as np

from ..sim.plant import RoverParams
from . import channels
from .series import Series


class Objective:
    """One channel's objective: RMS of simulated minus measured output for a batch of sets.

    Runs only that channel (:mod:`companion.ident.channels`, respond's model step for step);
    the speed channel sees the turn rate of the turn-rate model in ``base``."""

    def __init__(self, series: Series, base: RoverParams, which: int, speed_scale: float):
        self.series, self.base, self.which = series, base, which
        self.speed_scale = speed_scale      # the top speed the turn-rate coupling is a share of
        self.measured = series.yaw_rate if which == 1 else series.speed
        self.evaluations = 0
        self._omega: dict[float, np.ndarray] = {}
        self._speed: dict[float, np.ndarray] = {}

    def _speed_grid(self, dt: float) -> np.ndarray:
        """The measured speed on the grid (linear between samples): what the turn-rate
        coupling reads in place of a speed model not yet fitted."""
        if dt not in self._speed:
            s = self.series
            g = channels.Grid.of(s.t, dt)
            self._speed[dt] = np.interp(s.t[0] + dt * np.arange(g.steps), s.t, s.speed)
        return self._speed[dt]

    def _turn_rate(self, p: RoverParams, n: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
        s = self.series
        return channels.turn_rate(s.t, s.yaw_rate_cmd, n, dt, float(s.yaw_rate[0]),
                                  p.yaw_delay, p.yaw_bandwidth, p.max_yaw_rate,
                                  p.max_yaw_accel, p.yaw_decel, p.speed_turn_coupling,
                                  self._speed_grid(dt), self.speed_scale, p.min_turn_radius,
                                  p.max_lat_accel, p.yaw_overshoot, p.yaw_overshoot_s)

    def _omega_grid(self, dt: float) -> np.ndarray:
        if dt not in self._omega:
            self._omega[dt] = self._turn_rate(self.base, 1, dt)[1][:, 0]
        return self._omega[dt]

    def cost(self, values: dict[str, np.ndarray], n: int, dt: float,
             per_log: bool = False) -> np.ndarray:
        """RMS of each of the ``n`` parameter sets over the series: shape (n,); with
        ``per_log``, over each joined log apart: shape (logs, n)."""
        s = self.series
        p = self.base.with_(**values)
        if self.which == 1:
            out, _ = self._turn_rate(p, n, dt)
        else:
            out = channels.speed(s.t, s.speed_cmd, self._omega_grid(dt), n, dt,
                                 float(s.speed[0]), p.speed_delay, p.w_c, p.max_speed,
                                 p.max_accel, p.decel, p.turn_speed_coupling, p.max_yaw_rate,
                                 p.speed_overshoot, p.speed_overshoot_s)
        self.evaluations += n
        err = out - self.measured[:, None]
        if per_log:
            return np.array([np.sqrt(np.mean(err[k] ** 2, axis=0)) for k in s.segments])
        return np.sqrt(np.mean(err * err, axis=0))
