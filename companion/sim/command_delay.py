"""The commands in flight through each channel's pure delay: ring buffers on a fixed step, per
vehicle (the rover model's, the compiled plant's and :mod:`companion.sim.response`'s)."""

from __future__ import annotations

import numpy as np

from ..core.signals import Num


def delay_steps(speed_delay: Num, yaw_delay: Num, h: float, n: int | None) -> np.ndarray:
    """[channel (speed, turn rate), vehicle]: each pure delay in whole steps of ``h``,
    ``round(delay / h)`` (int64; one column for one vehicle)."""
    return np.stack([np.broadcast_to(np.rint(np.asarray(d, dtype=float) / h).astype(np.int64),
                                     (1 if n is None else n,)) for d in (speed_delay, yaw_delay)])


class CommandDelay:
    """Commands in flight through a pure delay (per channel, per vehicle), on a fixed step.

    ``push(speed, yaw_rate, h)`` stores the commands given now and returns those given
    ``round(delay / h)`` steps ago (zero before any). The step ``h`` is fixed by the first push.
    """

    def __init__(self, speed_delay: Num, yaw_delay: Num, n: int | None = None):
        self.speed_delay, self.yaw_delay, self.n = speed_delay, yaw_delay, n
        self.h: float | None = None

    def _setup(self, h: float) -> None:
        self.h = h
        shape = () if self.n is None else (self.n,)
        self._lags = delay_steps(self.speed_delay, self.yaw_delay, h, self.n)
        self._lag = [lag.reshape(shape) for lag in self._lags]
        self._size = int(max(lag.max(initial=0) for lag in self._lag)) + 1
        # both channels' rings in one array (the compiled plant takes it whole), one view each
        self._ring = np.zeros((2, self._size) + shape)
        self._buf = [self._ring[0], self._ring[1]]
        self._cols = None if self.n is None else np.arange(self.n)
        self._flat = [buf.reshape(-1) for buf in self._buf]
        # one delay for every vehicle (the usual case) reads a whole row, no gather
        self._uniform = [int(lag.flat[0]) if lag.size and np.all(lag == lag.flat[0]) else None
                         for lag in self._lag]
        self._k = 0

    def advance(self, h: float) -> int:
        """The slot this push writes (the step count so far), the step ``h`` checked."""
        if self.h is None:
            self._setup(h)
        elif abs(h - self.h) > 1e-12:
            raise ValueError(f"a delayed plant needs a fixed step: {self.h} s, then {h} s")
        k = self._k
        self._k = k + 1
        return k

    @property
    def ring(self) -> np.ndarray:
        """The ring buffers, [channel (speed, turn rate), slot, vehicle]: slot k % size holds
        push k (after :meth:`advance`)."""
        return self._ring

    @property
    def lags(self) -> np.ndarray:
        """[channel, vehicle]: how many pushes back each command comes out (int64)."""
        return self._lags

    def push(self, speed: Num, yaw_rate: Num, h: float) -> tuple[Num, Num]:
        k = self.advance(h)
        size = self._size
        out = []
        for buf, flat, lag, uniform, value in zip(self._buf, self._flat, self._lag, self._uniform,
                                                  (speed, yaw_rate), strict=True):
            buf[k % size] = value
            if uniform is not None:
                row = buf[(k - uniform) % size]
                out.append(float(row) if self._cols is None else row.copy())
            else:
                out.append(flat.take(((k - lag) % size) * self.n + self._cols))
        return out[0], out[1]
