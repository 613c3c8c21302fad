"""The estimate's noise at a stand still: what the tracker is fed of the receiver and the EKF
while the rover does not move (issue 44, item 4).

The robust tuner simulates white noise on the measured pose (``RobustConfig.noise_pos`` /
``noise_yaw``, EKF-like defaults). A vehicle on noisier GNSS deserves gains tuned for its own
noise, and the manoeuvre ``calibrate`` flies stands still before it moves and after it stops, so
the log holds what is needed: the pose samples where no setpoint asks for motion, none did for
``SETTLE_S`` before, and the rover reads at rest.

Only the white part is measured, from second differences: for white noise of standard
deviation sigma, ``x[k+1] - 2 x[k] + x[k-1]`` has variance ``6 sigma^2``, and a slow drift (the
receiver's wander, a creeping rover) all but cancels in it. The slow wander is not noise a
filter or gains could take out (docs/gnss.md): it is the floor of any tracker fed the estimate.
Pure: arrays in, figures out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SETTLE_S = 2.0          # s after the last setpoint that asked for motion before a sample counts
STILL_SPEED = 0.05      # m/s: a rover reading faster than this is not at rest
STILL_TURN = 0.02       # rad/s
MIN_RUN = 20            # samples in a row: a shorter stand still says little
MIN_SAMPLES = 80        # samples over all runs (2 s at 40 Hz)


@dataclass(frozen=True)
class EstimateNoise:
    """The white noise of the pose estimate at a stand still, per axis."""

    position_m: float
    yaw_rad: float
    samples: int            # pose samples it was measured from
    seconds: float          # of stand still they span

    def describe(self) -> str:
        return (f"{1000 * self.position_m:.1f} mm, {math.degrees(self.yaw_rad):.2f} deg "
                f"(white, over {self.seconds:.0f} s at a stand still)")


def still_mask(t: np.ndarray, speed: np.ndarray, yaw_rate: np.ndarray, cmd_t: np.ndarray | None,
               moving_cmd: np.ndarray | None) -> np.ndarray:
    """True where the rover stands still: no setpoint asking for motion in force or within
    ``SETTLE_S`` before, and its speed and turn rate read at rest. ``moving_cmd``: per setpoint
    (at ``cmd_t``), whether it asked for motion."""
    still = (np.abs(speed) < STILL_SPEED) & (np.abs(yaw_rate) < STILL_TURN)
    if cmd_t is not None and moving_cmd is not None and len(cmd_t):
        moving_t = cmd_t[moving_cmd]
        if len(moving_t):
            # the last moving setpoint at or before each sample, and whether the setpoint in
            # force there still asks for motion
            k = np.searchsorted(moving_t, t, side="right") - 1
            since = np.where(k >= 0, t - moving_t[np.maximum(k, 0)], np.inf)
            j = np.searchsorted(cmd_t, t, side="right") - 1
            in_force = np.where(j >= 0, moving_cmd[np.maximum(j, 0)], False)
            still &= (since >= SETTLE_S) & ~in_force
    return still


def measure(t: np.ndarray, x: np.ndarray, y: np.ndarray, yaw: np.ndarray,
            still: np.ndarray) -> EstimateNoise | None:
    """The white noise of (x, y, yaw) over the runs of ``still`` samples (None: too little
    stand still to say)."""
    d2_pos: list[np.ndarray] = []
    d2_yaw: list[np.ndarray] = []
    samples, seconds = 0, 0.0
    edges = np.flatnonzero(np.diff(np.concatenate(([0], still.astype(np.int8), [0]))))
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        if end - start < MIN_RUN:
            continue
        run = slice(start, end)
        xs, ys = x[run], y[run]
        ws = np.unwrap(yaw[run])
        d2_pos += [xs[2:] - 2 * xs[1:-1] + xs[:-2], ys[2:] - 2 * ys[1:-1] + ys[:-2]]
        d2_yaw.append(ws[2:] - 2 * ws[1:-1] + ws[:-2])
        samples += end - start
        seconds += float(t[end - 1] - t[start])
    if samples < MIN_SAMPLES:
        return None
    pos = np.concatenate(d2_pos)
    turn = np.concatenate(d2_yaw)
    pos, turn = pos[np.isfinite(pos)], turn[np.isfinite(turn)]
    if not len(pos) or not len(turn):
        return None
    return EstimateNoise(position_m=float(np.sqrt(np.mean(pos ** 2) / 6.0)),
                         yaw_rad=float(np.sqrt(np.mean(turn ** 2) / 6.0)),
                         samples=int(samples), seconds=seconds)


def of_flight(flight) -> EstimateNoise | None:
    """The stand-still noise of a :class:`companion.logs.logread.Flight`'s pose estimate."""
    cmd_t = moving = None
    if flight.cmd_t is not None and flight.speed_cmd is not None:
        cmd_t = np.asarray(flight.cmd_t, dtype=float)
        speed_cmd = np.asarray(flight.speed_cmd, dtype=float)
        turn_cmd = (np.asarray(flight.yaw_rate_cmd, dtype=float)
                    if flight.yaw_rate_cmd is not None else np.zeros_like(speed_cmd))
        # NaN (PX4's velocity vectors carry no turn rate) asks for no turn by itself
        moving = (speed_cmd != 0.0) | (np.nan_to_num(turn_cmd) != 0.0)
    t = np.asarray(flight.t, dtype=float)
    still = still_mask(t, np.asarray(flight.speed, dtype=float),
                       np.asarray(flight.yaw_rate, dtype=float), cmd_t, moving)
    return measure(t, np.asarray(flight.x, dtype=float), np.asarray(flight.y, dtype=float),
                   np.asarray(flight.yaw, dtype=float), still)
