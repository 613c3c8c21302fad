"""How vehicle time relates to wall time: paced (real time x speedup) or lockstep.

:class:`Pacer` maps wall seconds to vehicle microseconds from an anchor point; re-anchoring after
a lockstep stretch or a stall keeps it from rushing to catch up. :class:`LockstepGate` says
whether the plant may run on to its next telemetry tick: only once a setpoint has answered the
last telemetry sent, or the wall-clock timeout has passed; and it only holds the plant back while
the companion is actually streaming (a setpoint within the last second of vehicle time).
No clock is read here: callers pass wall times in.
"""

from __future__ import annotations


class Pacer:
    def __init__(self, speedup: float, max_lag: float = 0.25):
        self.speedup = speedup
        self.max_lag = max_lag      # wall s behind schedule before we give up catching up
        self._wall0 = 0.0
        self._t0_us = 0

    def anchor(self, wall: float, t_us: int) -> None:
        self._wall0, self._t0_us = wall, t_us

    def vehicle_us(self, wall: float) -> int:
        return self._t0_us + int((wall - self._wall0) * self.speedup * 1e6)

    def wall_at(self, t_us: int) -> float:
        return self._wall0 + (t_us - self._t0_us) * 1e-6 / self.speedup

    def behind(self, wall: float, t_us: int) -> bool:
        """True when the plant is so far behind schedule that it should re-anchor, not rush."""
        return wall - self.wall_at(t_us) > self.max_lag


class LockstepGate:
    def __init__(self, timeout: float, streaming_window_us: int = 1_000_000):
        self.timeout = timeout
        self.streaming_window_us = streaming_window_us
        self._last_setpoint_us: int | None = None
        self._waiting_since: float | None = None  # wall time telemetry went out unanswered
        self.timeouts = 0

    def engaged(self, t_us: int) -> bool:
        """Lockstep holds the plant only while setpoints are coming (within the last second)."""
        last = self._last_setpoint_us
        return last is not None and t_us - last < self.streaming_window_us

    def telemetry_sent(self, wall: float) -> None:
        self._waiting_since = wall

    def setpoint_arrived(self, t_us: int) -> None:
        self._last_setpoint_us = t_us
        self._waiting_since = None

    def deadline(self) -> float | None:
        """Wall time until which the plant waits, or None when it may advance."""
        return None if self._waiting_since is None else self._waiting_since + self.timeout

    def expire(self) -> None:
        self._waiting_since = None
        self.timeouts += 1
