"""Pose telemetry as a real link delivers it: sampled, noisy, late, sometimes lost.

A sample is taken once per tick (ATTITUDE and LOCAL_POSITION_NED of one tick share it, and its
time_boot_ms), gets Gaussian noise on position and yaw, waits ``latency`` seconds of vehicle time,
and each message is dropped independently with probability ``dropout``. Link faults on top, each
per message with its own probability (the generator is only drawn from for the ones asked for,
so a seed gives the same run as before they existed):

* ``duplicate``: the message goes out twice, back to back;
* ``reorder``: the message is held back ``REORDER_DELAY_US`` extra, so later ones overtake it;
* ``burst``: the link stalls for ``BURST_US``: everything due meanwhile leaves at once at the end.

Pure: the random generator is seeded, times are vehicle microseconds.
"""

from __future__ import annotations

import heapq
import random
from dataclasses import dataclass

from companion.core.angles import wrap


@dataclass(frozen=True)
class TelemetryConfig:
    noise_pos: float = 0.0   # m, standard deviation on x and y
    noise_yaw: float = 0.0   # rad, standard deviation on yaw
    latency: float = 0.0     # s of vehicle time between sampling and sending
    dropout: float = 0.0     # probability each pose message is lost
    seed: int = 0
    duplicate: float = 0.0   # probability a pose message is sent twice
    reorder: float = 0.0     # probability a pose message is overtaken by later ones
    burst: float = 0.0       # probability (per message) the link stalls, then bursts


REORDER_DELAY_US = 60_000    # vehicle us a reordered message is held back
BURST_US = 100_000           # vehicle us a stall lasts; its messages then leave together


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
        # (release time, sequence, message id, sample): a heap, FIFO among equal times.
        self._queue: list[tuple[int, int, int, PoseSample]] = []
        self._seq = 0
        self._stall_until = -1
        self.dropped = 0
        self.duplicated = self.reordered = self.bursts = 0

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
        c, rng = self.config, self._rng
        if c.dropout > 0.0 and rng.random() < c.dropout:
            self.dropped += 1
            return
        release = now_us + self._latency_us
        if c.burst > 0.0 and now_us >= self._stall_until and rng.random() < c.burst:
            self._stall_until = now_us + BURST_US
            self.bursts += 1
        if c.reorder > 0.0 and rng.random() < c.reorder:
            release += REORDER_DELAY_US
            self.reordered += 1
        if now_us < self._stall_until:
            release = max(release, self._stall_until + self._latency_us)
        copies = 2 if c.duplicate > 0.0 and rng.random() < c.duplicate else 1
        self.duplicated += copies - 1
        for _ in range(copies):
            heapq.heappush(self._queue, (release, self._seq, msg_id, sample))
            self._seq += 1

    def next_release_us(self) -> int | None:
        return self._queue[0][0] if self._queue else None

    def release(self, now_us: int) -> list[tuple[int, PoseSample]]:
        """Messages whose time has come, in release order (queue order among equals)."""
        out = []
        queue = self._queue
        while queue and queue[0][0] <= now_us:
            _, _, msg_id, sample = heapq.heappop(queue)
            out.append((msg_id, sample))
        return out
