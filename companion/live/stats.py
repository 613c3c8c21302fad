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
period that got no timely setpoint: a sample the vehicle's clock says should have come but did
not (lost or refused; ``gaps``) or a cycle whose latency exceeded the period (an overrun).
``backlog`` counts samples read with no idle wait since the previous one was answered: an upper
bound on how often the loop had fallen behind (it also counts a preemption right after a send,
and in lockstep a plant that answered before the loop looked again).

Gaps are counted per tracking segment from elapsed vehicle time, not interval by interval: a
vehicle need not deliver at even intervals. ArduPilot sends a message at the first tick of its
scheduler (50 Hz on Rover) at or after the message's due time, and the due times run at the
rate asked for; so at 40 Hz LOCAL_POSITION_NED comes 20, 20, 20, 40 ms apart (mean 25 ms),
each sample up to one tick (0.8 period; it refuses rates above 0.8 x its loop rate) plus about
a millisecond late, and a 40 ms interval is not a lost sample. After k intervals received in a
segment that began at vehicle time t0 the stream is ``behind = (t - t0) / period - k`` periods
behind its nominal pace: a lost sample adds one period for good, lateness comes and goes
within that tick. The segment's gaps are the largest rise of ``behind`` above its lowest value
so far, in whole periods (less 0.05 for rounding):

    gaps = max over samples of floor(behind - min(behind so far) + 0.05)

On ArduPilot's stream that is 0 (lateness never varies by 0.95 period), a lost sample is counted
once a sample as late as the least late one before it has arrived (within a pattern cycle,
four samples), and on evenly spaced samples it is the plain count of skipped periods. A gap
long enough to reset the tracker (:meth:`TrackingStats.lost`) counts its whole periods; a pause
or a failsafe counts nothing.
"""

from __future__ import annotations

import math

_BINS = 100_000   # 1 us bins: up to 100 ms, beyond goes in the last bin
GAP_TOLERANCE = 0.05  # periods: rounding; lateness up to 0.95 period is not a loss


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
        self.gaps = 0                   # samples that should have come and did not
        self.backlog = 0                # samples read with no idle wait since the previous one
        self.overruns = 0               # cycles whose latency exceeded the period
        self.mission_time = 0.0
        self._prev: tuple[float, float, float] | None = None   # mission t, vehicle t, e^2
        self._seg_t0 = 0.0              # vehicle time of the segment's first sample
        self._seg_intervals = 0         # intervals received in this segment
        self._seg_best = 0.0            # lowest `behind` so far (periods)
        self._seg_gaps = 0              # gaps counted in this segment

    def segment_start(self) -> None:
        """Tracking (re)starts: do not integrate across the pause, nor count it as missed."""
        self._prev = None

    def lost(self, seconds: float) -> None:
        """``seconds`` of vehicle time without a sample while tracking, long enough that the
        next sample starts a new segment (a tracker reset): its whole periods are missed."""
        if self.period is not None:
            self.gaps += max(0, round(seconds / self.period) - 1)

    def add(self, mission_t: float, vehicle_t: float, e2: float, latency: float,
            backlog: bool) -> None:
        self.cycles += 1
        self.mission_time = mission_t
        prev = self._prev
        if prev is None:
            self._seg_t0, self._seg_intervals = vehicle_t, 0
            self._seg_best, self._seg_gaps = 0.0, 0
        else:
            self.cost += 0.5 * (prev[2] + e2) * (mission_t - prev[0])
            self.intervals += 1
            self.span += vehicle_t - prev[1]
            if self.period is not None:
                self._count_gaps(vehicle_t)
        self._prev = (mission_t, vehicle_t, e2)
        if mission_t >= 0.5 * self.duration:
            self.steady_sum += e2
            self.steady_n += 1
        self.latency.add(latency)
        if backlog:
            self.backlog += 1
        if self.period is not None and latency > self.period:
            self.overruns += 1

    def _count_gaps(self, vehicle_t: float) -> None:
        """The module docstring's gap count, for one more interval of this segment."""
        self._seg_intervals += 1
        assert self.period is not None   # only called with a known period
        behind = (vehicle_t - self._seg_t0) / self.period - self._seg_intervals
        if behind < self._seg_best:
            self._seg_best = behind
        missing = math.floor(behind - self._seg_best + GAP_TOLERANCE)
        if missing > self._seg_gaps:
            self.gaps += missing - self._seg_gaps
            self._seg_gaps = missing

    @property
    def f_cost(self) -> float:
        return math.sqrt(self.cost)

    @property
    def steady_rms(self) -> float:
        return math.sqrt(self.steady_sum / self.steady_n) if self.steady_n else math.nan

    @property
    def loop_rate_hz(self) -> float:
        return self.intervals / self.span if self.span > 0 else math.nan
