"""What a live run measured: tracking error, loop rate, latency, missed cycles.

Tracking metrics are the paper's (Section 5.3) on the telemetry samples themselves, with
p = the measured position and t = mission time (vehicle clock):

    f_cost     = sqrt( sum over sample intervals of (e_k^2 + e_{k+1}^2) / 2 * dt_k )
    steady_rms = sqrt( mean of e_k^2 over samples with mission time >= duration / 2 )

The trapezoidal sum is the integral of :mod:`companion.sim.batch` sampled at the telemetry rate (at
40 Hz it differs from batch's 1 ms integration by about 0.2 % on the paper's ellipse; a
rectangle sum would add 2-3 % from the large initial error). Intervals are only summed inside
one tracking segment: a pause or a failsafe is not integrated over.

Latency is companion wall time from reading a LOCAL_POSITION_NED to having sent its setpoint,
kept in a 1 us histogram (constant memory at 1 kHz for hours). A *missed* cycle is a telemetry
period that got no timely setpoint: a gap in the vehicle's sample times (a sample lost or
refused) or a cycle whose latency exceeded the period (an overrun). ``backlog`` counts samples
read with no idle wait since the previous one was answered: an upper bound on how often the
loop had fallen behind (it also counts a preemption right after a send, and in lockstep a
plant that answered before the loop looked again).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

_BINS = 100_000   # 1 us bins: up to 100 ms, beyond goes in the last bin


class LatencyHistogram:
    def __init__(self) -> None:
        self.counts = [0] * (_BINS + 1)
        self.n = 0
        self.max_s = 0.0

    def add(self, seconds: float) -> None:
        i = int(seconds * 1e6)
        self.counts[i if i < _BINS else _BINS] += 1
        self.n += 1
        if seconds > self.max_s:
            self.max_s = seconds

    def percentile(self, q: float) -> float:
        """The q-th percentile (0-100) in seconds, to the microsecond; NaN when empty."""
        if self.n == 0:
            return math.nan
        rank = max(1, math.ceil(q / 100.0 * self.n))
        seen = 0
        for i, c in enumerate(self.counts):
            seen += c
            if seen >= rank:
                return self.max_s if i == _BINS else min((i + 1) * 1e-6, self.max_s)
        return self.max_s


class TrackingStats:
    def __init__(self, duration: float, period: float | None):
        self.duration = duration
        self.period = period            # nominal telemetry period (s); None: unknown
        self.latency = LatencyHistogram()
        self.cycles = 0
        self.cost = 0.0
        self.steady_sum = 0.0
        self.steady_n = 0
        self.intervals = 0
        self.span = 0.0                 # vehicle seconds covered by those intervals
        self.gaps = 0                   # telemetry periods with no sample
        self.backlog = 0                # samples read with no idle wait since the previous one
        self.overruns = 0               # cycles whose latency exceeded the period
        self.mission_time = 0.0
        self._prev: tuple[float, float, float] | None = None   # mission t, vehicle t, e^2

    def segment_start(self) -> None:
        """Tracking (re)starts: do not integrate across the pause."""
        self._prev = None

    def add(self, mission_t: float, vehicle_t: float, e2: float, latency: float,
            backlog: bool) -> None:
        self.cycles += 1
        self.mission_time = mission_t
        prev = self._prev
        if prev is not None:
            self.cost += 0.5 * (prev[2] + e2) * (mission_t - prev[0])
            dt = vehicle_t - prev[1]
            self.intervals += 1
            self.span += dt
            if self.period is not None:
                skipped = round(dt / self.period) - 1
                if skipped > 0:
                    self.gaps += skipped
        self._prev = (mission_t, vehicle_t, e2)
        if mission_t >= 0.5 * self.duration:
            self.steady_sum += e2
            self.steady_n += 1
        self.latency.add(latency)
        if backlog:
            self.backlog += 1
        if self.period is not None and latency > self.period:
            self.overruns += 1

    @property
    def f_cost(self) -> float:
        return math.sqrt(self.cost)

    @property
    def steady_rms(self) -> float:
        return math.sqrt(self.steady_sum / self.steady_n) if self.steady_n else math.nan

    @property
    def loop_rate_hz(self) -> float:
        return self.intervals / self.span if self.span > 0 else math.nan


@dataclass
class RunResult:
    """The result object ``companion run --json`` and ``companion demo --json`` print."""

    reason: str                      # mission_done, signal, aborted, failsafe: ..., ...
    exit_code: int
    f_cost: float
    steady_rms: float
    setpoints_sent: int
    telemetry_received: int          # LOCAL_POSITION_NED from the vehicle, refused ones included
    telemetry_rejected: dict[str, int]
    cycles: int                      # tracking cycles (one setpoint each)
    loop_rate_hz: float              # tracking cycles per vehicle second
    latency_p50_ms: float
    latency_p99_ms: float
    latency_max_ms: float
    missed_cycles: int               # gaps + overruns
    overruns: int
    duration_s: float                # mission time tracked
    wall_s: float                    # companion wall time from connect to exit
    rate_requested_hz: float
    rate_accepted_hz: float | None
    autopilot: str
    sysid: int
    gains: dict[str, Any]
    gains_source: str
    limits: dict[str, float]
    failsafes: int
    hold_confirmed: bool
    mission: str
    extra: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.update(d.pop("extra"))
        # JSON has no NaN/inf: say null instead.
        for key, value in d.items():
            if isinstance(value, float) and not math.isfinite(value):
                d[key] = None
        return d
