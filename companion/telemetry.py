"""Pose telemetry checked before it can reach the controller.

A control cycle is driven by LOCAL_POSITION_NED (position, the vehicle's velocity estimate and
``time_boot_ms``); the yaw comes from the newest ATTITUDE. A sample is refused, counted by
reason, and never reaches the filter when:

* ``other_source``: it is not from the vehicle we follow (another system or component id);
* ``not_finite``: a field used is NaN or infinite;
* ``time_backwards`` / ``duplicate``: its time_boot_ms is before / equal to the last sample's
  (out-of-order delivery, a repeated frame, or a vehicle that restarted);
* ``no_attitude``: no valid ATTITUDE within ``max_attitude_age`` of the position.

Times are the vehicle's (``time_boot_ms``), never the companion's clock. Pure: no I/O, no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

_finite = math.isfinite
REASONS = ("other_source", "not_finite", "time_backwards", "duplicate", "no_attitude")
RESTART_JUMP_MS = 1000   # a step back this large looks like a vehicle reboot, not reordering


@dataclass(slots=True)
class Sample:
    """One accepted pose: vehicle time ``t`` (s) and ``time_boot_ms``, NED position, yaw."""

    time_boot_ms: int
    t: float
    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    yaw_rate: float


@dataclass
class TelemetryCheck:
    sysid: int
    compid: int
    max_attitude_age: float = 0.5          # s of vehicle time between ATTITUDE and position
    rejected: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REASONS, 0))
    received: int = 0                      # LOCAL_POSITION_NED from our vehicle
    accepted: int = 0
    backwards_streak: int = 0              # refused in a row for going back a long way
    _last_ms: int | None = None
    _att_ms: int | None = None
    _yaw: float = 0.0
    _yaw_rate: float = 0.0

    def _ours(self, msg: Any) -> bool:
        if msg.get_srcSystem() == self.sysid and msg.get_srcComponent() == self.compid:
            return True
        self.rejected["other_source"] += 1
        return False

    def attitude(self, msg: Any) -> None:
        """Keep the yaw of a valid ATTITUDE for the next position sample."""
        if not self._ours(msg):
            return
        if not (_finite(msg.yaw) and _finite(msg.yawspeed)):
            # The attitude source is bad right now: drop the yaw held too, so no position is
            # paired with it until a valid ATTITUDE arrives.
            self.rejected["not_finite"] += 1
            self._att_ms = None
            return
        ms = msg.time_boot_ms
        if self._att_ms is not None and ms < self._att_ms:
            return   # an older attitude than the one held: keep the newer
        self._att_ms, self._yaw, self._yaw_rate = ms, msg.yaw, msg.yawspeed

    def position(self, msg: Any) -> Sample | None:
        """The checked sample for a LOCAL_POSITION_NED, or None (refused and counted)."""
        if not self._ours(msg):
            return None
        self.received += 1
        ms = msg.time_boot_ms
        x, y, vx, vy = msg.x, msg.y, msg.vx, msg.vy
        if not (_finite(x) and _finite(y) and _finite(vx) and _finite(vy)):
            self.rejected["not_finite"] += 1
            return None
        last = self._last_ms
        if last is not None and ms <= last:
            if ms == last:
                self.rejected["duplicate"] += 1
            else:
                self.rejected["time_backwards"] += 1
                if last - ms >= RESTART_JUMP_MS:
                    self.backwards_streak += 1
            return None
        att = self._att_ms
        if att is None or abs(ms - att) > self.max_attitude_age * 1000.0:
            self.rejected["no_attitude"] += 1
            return None
        self._last_ms = ms
        self.backwards_streak = 0
        self.accepted += 1
        return Sample(ms, ms * 1e-3, x, y, self._yaw, vx, vy, self._yaw_rate)

    def restart_timeline(self) -> None:
        """Accept the next sample whatever its time (after the vehicle rebooted on purpose)."""
        self._last_ms = self._att_ms = None
        self.backwards_streak = 0

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())
