"""Pose telemetry checked before it can reach the controller.

A control cycle is driven by LOCAL_POSITION_NED (position, the vehicle's velocity estimate and
``time_boot_ms``); the yaw comes from the newest ATTITUDE. A sample is refused, counted by
reason, and never reaches the filter when:

* ``other_source``: it is not from the vehicle we follow (another system or component id);
* ``not_finite``: a field used is NaN or infinite;
* ``out_of_range``: a field is finite but no rover can have it (a position beyond
  ``MAX_POSITION`` from the EKF origin, a speed beyond ``MAX_SPEED``, a yaw outside
  [-2 pi, 2 pi], a turn rate beyond ``MAX_YAW_RATE``): corrupted or forged, never fed on;
* ``time_jump``: its time_boot_ms is more than ``RESTART_JUMP_MS`` after the last sample's. One
  such sample may be a corrupted or forged clock; the jump is believed (and the sample taken)
  only when the next sample continues from it. A real outage costs one sample this way;
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
REASONS = ("other_source", "not_finite", "out_of_range", "time_jump", "time_backwards",
           "duplicate", "no_attitude")
RESTART_JUMP_MS = 1000   # a step back this large looks like a vehicle reboot, not reordering
MAX_POSITION = 1.0e6     # m from the EKF origin (a local frame is a few km across)
MAX_SPEED = 1.0e3        # m/s
MAX_YAW = 2.0 * math.pi  # rad (ATTITUDE says [-pi, pi]; some autopilots say [0, 2 pi])
MAX_YAW_RATE = 1.0e3     # rad/s


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
    _jump_ms: int | None = None            # a sample that jumped ahead, waiting for a second

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
        if abs(msg.yaw) > MAX_YAW or abs(msg.yawspeed) > MAX_YAW_RATE:
            self.rejected["out_of_range"] += 1
            return
        ms = msg.time_boot_ms
        held = self._att_ms
        if held is not None and held - RESTART_JUMP_MS <= ms < held:
            return   # an older attitude than the one held: keep the newer
        # (one far behind the held one replaces it: the held one was from the future, a
        # corrupted clock, or the vehicle rebooted)
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
        if (abs(x) > MAX_POSITION or abs(y) > MAX_POSITION or abs(vx) > MAX_SPEED
                or abs(vy) > MAX_SPEED):
            self.rejected["out_of_range"] += 1
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
        if last is not None and ms - last > RESTART_JUMP_MS:
            jump = self._jump_ms
            if jump is None or not 0 < ms - jump <= RESTART_JUMP_MS:
                self._jump_ms = ms
                self.rejected["time_jump"] += 1
                return None
        att = self._att_ms
        if att is None or abs(ms - att) > self.max_attitude_age * 1000.0:
            self.rejected["no_attitude"] += 1
            return None
        self._jump_ms = None
        self._last_ms = ms
        self.backwards_streak = 0
        self.accepted += 1
        return Sample(ms, ms * 1e-3, x, y, self._yaw, vx, vy, self._yaw_rate)

    @property
    def last_ms(self) -> int | None:
        """The time_boot_ms of the last accepted sample (None before one, or after
        :meth:`restart_timeline`)."""
        return self._last_ms

    def restart_timeline(self) -> None:
        """Accept the next sample whatever its time (after the vehicle rebooted on purpose)."""
        self._last_ms = self._att_ms = self._jump_ms = None
        self.backwards_streak = 0

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())


def clock_went_back(last_ms: int | None, clock_ms: int) -> bool:
    """The vehicle's clock read as ``clock_ms`` (a SYSTEM_TIME, ATTITUDE or LOCAL_POSITION_NED
    it sent) is more than ``RESTART_JUMP_MS`` before ``last_ms``, the last accepted sample's:
    it rebooted. Unknown (``last_ms`` None) is not a reboot."""
    return last_ms is not None and clock_ms < last_ms - RESTART_JUMP_MS
