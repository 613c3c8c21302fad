"""Pose telemetry as a real link delivers it: sampled, noisy, late, sometimes lost.

A sample is taken once per tick (ATTITUDE and LOCAL_POSITION_NED of one tick share it, and its
time_boot_ms), gets Gaussian noise on position and yaw, waits ``latency`` seconds of vehicle time,
and each message is dropped independently with probability ``dropout``. Pure: the random
generator is seeded, times are vehicle microseconds.
"""

from __future__ import annotations

import random
from collections import deque
from dataclasses import dataclass

from companion.angles import wrap


@dataclass(frozen=True)
class TelemetryConfig:
    noise_pos: float = 0.0   # m, standard deviation on x and y
    noise_yaw: float = 0.0   # rad, standard deviation on yaw
    latency: float = 0.0     # s of vehicle time between sampling and sending
    dropout: float = 0.0     # probability each pose message is lost
    seed: int = 0


@dataclass(frozen=True)
class PoseSample:
    time_boot_ms: int
    x: float
    y: float
    yaw: float       # wrapped to (-pi, pi]
    vx: float
    vy: float
    yaw_rate: float


class TelemetryPipe:
    def __init__(self, config: TelemetryConfig = TelemetryConfig()):
        self.config = config
        self._rng = random.Random(config.seed)
        self._latency_us = int(round(config.latency * 1e6))
        self._queue: deque[tuple[int, int, PoseSample]] = deque()
        self.dropped = 0

    def sample(self, now_us: int, x: float, y: float, yaw: float, vx: float, vy: float,
               yaw_rate: float) -> PoseSample:
        c, rng = self.config, self._rng
        if c.noise_pos > 0.0:
            x += rng.gauss(0.0, c.noise_pos)
            y += rng.gauss(0.0, c.noise_pos)
        if c.noise_yaw > 0.0:
            yaw += rng.gauss(0.0, c.noise_yaw)
        return PoseSample(now_us // 1000, x, y, wrap(yaw), vx, vy, yaw_rate)

    def push(self, now_us: int, msg_id: int, sample: PoseSample) -> None:
        if self.config.dropout > 0.0 and self._rng.random() < self.config.dropout:
            self.dropped += 1
            return
        self._queue.append((now_us + self._latency_us, msg_id, sample))

    def next_release_us(self) -> int | None:
        return self._queue[0][0] if self._queue else None

    def release(self, now_us: int) -> list[tuple[int, PoseSample]]:
        """Messages whose time has come, oldest first (FIFO: the latency is constant)."""
        out = []
        while self._queue and self._queue[0][0] <= now_us:
            _, msg_id, sample = self._queue.popleft()
            out.append((msg_id, sample))
        return out
