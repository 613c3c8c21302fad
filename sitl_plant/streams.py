"""Which messages are due when: MAV_CMD_SET_MESSAGE_INTERVAL bookkeeping, on vehicle time.

Follows ArduPilot (libraries/GCS_MAVLink/GCS_Common.cpp): about 1 Hz until asked; interval -1
disables, 0 restores the default; a rate above 0.8 x the scheduler loop rate is refused with
MAV_RESULT_DENIED and the old rate stays. Due times sit on multiples of each interval on the boot
clock, so streams at the same (or commensurate) rates fall on the same ticks: ATTITUDE and
LOCAL_POSITION_NED at one rate always share a tick and a time_boot_ms.

With ``tick_aligned`` a message due between two scheduler ticks goes out on the next tick, as
ArduPilot's scheduler sends it: 40 Hz on a 50 Hz loop arrives at 20, 20, 20, 40 ms intervals.

Times are integer microseconds, so long runs do not drift.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

HEARTBEAT = 0
SYS_STATUS = 1
ATTITUDE = 30
LOCAL_POSITION_NED = 32
GLOBAL_POSITION_INT = 33
EKF_STATUS_REPORT = 193     # off until asked (the companion asks for it at 5 Hz)
GPS_GLOBAL_ORIGIN = 49       # not streams: sent on MAV_CMD_REQUEST_MESSAGE
HOME_POSITION = 242
MISSION_CURRENT = 42         # a stream once asked for (and sent whenever the item changes)
GPS_RAW_INT = 24             # the receiver's fix type and claimed accuracy (sitl_plant.status)

# Emission order within one tick: ATTITUDE just before LOCAL_POSITION_NED.
STREAM_ORDER = (HEARTBEAT, SYS_STATUS, EKF_STATUS_REPORT, GPS_RAW_INT, ATTITUDE,
                LOCAL_POSITION_NED, GLOBAL_POSITION_INT, MISSION_CURRENT)
DEFAULT_INTERVAL_US = {HEARTBEAT: 1_000_000, SYS_STATUS: 1_000_000,
                       ATTITUDE: 1_000_000, LOCAL_POSITION_NED: 1_000_000,
                       GLOBAL_POSITION_INT: 1_000_000, EKF_STATUS_REPORT: 1_000_000,
                       MISSION_CURRENT: 1_000_000, GPS_RAW_INT: 1_000_000}
RATE_CAP_FRACTION = 0.8

ACCEPTED, DENIED, FAILED = 0, 2, 4   # MAV_RESULT


@dataclass(frozen=True)
class IntervalReply:
    result: int
    text: str | None = None


class StreamSchedule:
    def __init__(self, loop_rate_hz: float, defaults: dict[int, int] | None = None,
                 tick_aligned: bool = False, initial: dict[int, int | None] | None = None):
        self.loop_rate_hz = loop_rate_hz
        self._tick = max(1, int(round(1e6 / loop_rate_hz))) if tick_aligned else 1
        self._defaults = dict(DEFAULT_INTERVAL_US if defaults is None else defaults)
        # `initial`: intervals at boot where they differ from the defaults (None: off until asked)
        self._interval: dict[int, int | None] = {**self._defaults, **(initial or {})}
        self._next: dict[int, int] = {m: 0 for m in self._interval}

    @property
    def max_rate_hz(self) -> float:
        return RATE_CAP_FRACTION * self.loop_rate_hz

    def interval_us(self, msg_id: int) -> int:
        """For MESSAGE_INTERVAL: -1 disabled, 0 not a stream we send."""
        if msg_id not in self._interval:
            return 0
        interval = self._interval[msg_id]
        return -1 if interval is None else interval

    def request(self, msg_id: float, interval_us: float, now_us: int) -> IntervalReply:
        """MAV_CMD_SET_MESSAGE_INTERVAL: param1 message id, param2 interval (us)."""
        if not (math.isfinite(msg_id) and math.isfinite(interval_us)):
            return IntervalReply(FAILED)
        mid = int(msg_id)
        if mid not in self._interval:
            return IntervalReply(DENIED, f"No ap_message for mavlink id ({mid})")
        if interval_us == -1:
            self._interval[mid] = None
            return IntervalReply(ACCEPTED)
        if interval_us < 0:
            return IntervalReply(FAILED)
        new = self._defaults[mid] if interval_us == 0 else int(round(interval_us))
        if new <= 0 or 1e6 / new > self.max_rate_hz + 1e-9:
            return IntervalReply(DENIED, f"Requested rate for message ID {mid} too fast")
        self._interval[mid] = new
        self._next[mid] = (now_us // new + 1) * new
        return IntervalReply(ACCEPTED)

    def _slot(self, due_us: int) -> int:
        """When a message due at ``due_us`` goes out: then, or on the next scheduler tick."""
        return -(-due_us // self._tick) * self._tick

    def next_due_us(self) -> int | None:
        dues = [self._slot(self._next[m]) for m, i in self._interval.items() if i is not None]
        return min(dues) if dues else None

    def due(self, now_us: int) -> list[int]:
        """Streams due at ``now_us`` in emission order; each is scheduled for its next slot."""
        out = []
        for mid in STREAM_ORDER:
            interval = self._interval.get(mid)
            if interval is None or self._slot(self._next[mid]) > now_us:
                continue
            out.append(mid)
            self._next[mid] = (now_us // interval + 1) * interval
        return out
