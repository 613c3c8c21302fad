"""Jumps of the receiver that its own class does not admit: multipath moving a "fixed" solution.

ArduPilot's EKF takes any GNSS position as at least 0.5 m uncertain, so a receiver that says
"RTK fixed" while multipath moves it by decimetres is followed: LOCAL_POSITION_NED slides over
a second or two to the jumped position, without a flag (docs/gnss.md). The slide is too slow to
tell from driving in one sample; the receiver's own step is not. :class:`JumpGuard`:

* keeps, at each new fix (GPS_RAW_INT's position), the receiver's position less the estimate's
  (a constant in good times, whatever the frames' origins: the antenna, the lag at the speed
  driven) and its median over the last ``baseline_fixes`` fixes;
* two fixes in a row that leave that baseline by more than ``threshold``, in the same direction,
  are a jump (one alone is a fix stamped late: the autopilot stamps a fix when it arrives, and
  a late one sits a speed x delay off); then it **rides through**: the position the controller
  gets is dead-reckoned with the estimate's velocity from the estimate before the jump, not the
  estimate sliding after the receiver;
* once two fixes in a row sit back on the baseline against the dead reckoning, and the estimate
  has come back to the dead-reckoned position (within ``settle``) or had ``back_wait`` s to,
  hands the estimate back, fading what the dead reckoning drifted out over ``blend_s`` (no
  step); an estimate that has not left the dead reckoning by a quarter of the jump in
  ``confirm`` s never followed one, and is handed back at once;
* after ``max_ride`` s of riding it gives up (:meth:`overdue`): the runner then holds the rover,
  and starts again from the estimate.

A receiver claiming more than ``max_h_acc`` (plain GPS) is not judged: its wander is not a jump.
Pure: no I/O, no clock.
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from dataclasses import dataclass, field

EARTH = 6378137.0                      # m: only differences of nearby fixes are taken


@dataclass
class JumpGuard:
    """Ride through receiver jumps (see the module docstring)."""

    threshold: float = 0.12            # m a fix may leave the baseline
    settle: float = 0.03               # m: the estimate back on the dead-reckoned position
    max_ride: float = 10.0             # s of riding through before giving up
    max_h_acc: float = 0.2             # m: a receiver claiming more is not judged
    confirm: float = 3.0               # s: an estimate that has not left the dead reckoning
    baseline_fixes: int = 7
    jumps: int = 0                     # jumps ridden through
    false_alarms: int = 0
    riding_since: float | None = None  # vehicle s the ride began (None: not riding)
    _origin: tuple[float, float] | None = None          # lat, lon (degrees) of the first fix
    _last_fix: tuple[int, int] | None = None
    _history: deque = field(default_factory=lambda: deque(maxlen=7))   # receiver - estimate
    _pending: tuple[float, float] | None = None          # one fix off the baseline (n, e)
    _last: tuple[float, float, float, float, float] | None = None   # t, x, y, vx, vy
    _before: tuple[float, float, float, float, float] | None = None  # the estimate at the last fix
    _dead: tuple[float, float] = (0.0, 0.0)              # the dead-reckoned position
    _back: bool = False                # the receiver is back on its baseline
    _apart: float = 0.0                # m: the most the estimate left the dead reckoning
    _calm: int = 0                     # fixes in a row back on the baseline while riding
    _anchor: tuple[float, float, float, float, float] | None = None   # the estimate before
    _size: float = 0.0                 # m: the jump ridden through
    _back_at: float = 0.0              # vehicle s the receiver came back
    _blend: tuple[float, tuple[float, float]] | None = None   # (s, offset) handing back
    back_wait: float = 3.0             # s after the receiver is back before the estimate is
    #                                    handed back however far it is (ArduPilot's EKF slides
    #                                    back over 1-3 s)
    blend_s: float = 2.0               # s the dead reckoning's drift fades out over
    stamp_slack: float = 0.1           # s: a fix's stamp against the estimate's sample

    def __post_init__(self) -> None:
        self._history = deque(maxlen=self.baseline_fixes)

    def fix(self, lat_e7: int, lon_e7: int, h_acc: float | None) -> str | None:
        """A GPS_RAW_INT: a line when a ride begins or the receiver is back, else None."""
        if (lat_e7 == 0 and lon_e7 == 0) or (lat_e7, lon_e7) == self._last_fix:
            return None                 # no fix, or the same fix again
        self._last_fix = (lat_e7, lon_e7)
        if self._last is None or (h_acc is not None and h_acc > self.max_h_acc):
            self._history.clear()
            return None
        lat, lon = lat_e7 * 1e-7, lon_e7 * 1e-7
        if self._origin is None:
            self._origin = (lat, lon)
        north = math.radians(lat - self._origin[0]) * EARTH
        east = math.radians(lon - self._origin[1]) * EARTH * math.cos(math.radians(lat))
        before, self._before = self._before, self._last
        if self.riding_since is None:
            return self._watch(north - self._last[1], east - self._last[2], before)
        return self._riding(north - self._dead[0], east - self._dead[1])

    def _off(self, dn: float, de: float) -> tuple[float, float] | None:
        """(n, e) this fix leaves the baseline by, if more than the threshold and what a change
        of speed since the baseline's fixes explains (the fix's stamp and the estimate's sample
        differ by up to ``stamp_slack`` s: at a new speed the difference moves by that much)."""
        if len(self._history) < self._history.maxlen:     # type: ignore[operator]
            return None
        h = self._history
        bn, be = statistics.median(x[0] for x in h), statistics.median(x[1] for x in h)
        bvx, bvy = statistics.median(x[2] for x in h), statistics.median(x[3] for x in h)
        assert self._last is not None
        doubt = self.stamp_slack * math.hypot(self._last[3] - bvx, self._last[4] - bvy)
        on, oe = dn - bn, de - be
        return (on, oe) if math.hypot(on, oe) > self.threshold + doubt else None

    def _watch(self, dn: float, de: float, before: tuple | None) -> str | None:
        off = self._off(dn, de)
        pending, self._pending = self._pending, off
        if off is None:
            assert self._last is not None
            self._history.append((dn, de, self._last[3], self._last[4]))
            return None
        if pending is None or self._anchor is None or \
                math.hypot(off[0] - pending[0], off[1] - pending[1]) > self.threshold:
            self._anchor = before   # one fix off: a late one, or the first of a jump
            return None
        # two in a row, the same way: a jump. Dead reckoning from the estimate of the fix
        # before the first of them (the estimate had not yet slid after it)
        self._pending, self.jumps, self._back, self._apart = None, self.jumps + 1, False, 0.0
        self._calm, self._size = 0, math.hypot(*off)
        t0, x0, y0, vx0, vy0 = self._anchor
        t, _, _, vx, vy = self._last  # type: ignore[misc]
        self._dead = (x0 + 0.5 * (vx0 + vx) * (t - t0), y0 + 0.5 * (vy0 + vy) * (t - t0))
        self.riding_since = t
        return (f"the receiver jumped {math.hypot(*off):.2f} m, still claiming its class: riding "
                f"through on the rover's own motion (at most {self.max_ride:g} s)")

    def _riding(self, dn: float, de: float) -> str | None:
        # against the dead reckoning: the jump itself, until two fixes in a row are back
        self._calm = self._calm + 1 if self._off(dn, de) is None else 0
        if self._calm >= 2 and not self._back:
            self._back = True
            self._back_at = self._last[0] if self._last is not None else 0.0
            return "the receiver is back: rejoining the estimate once it has followed"
        return None

    def position(self, t: float, x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        """An accepted LOCAL_POSITION_NED: the position to steer by (the estimate's, or the
        dead-reckoned one while riding through)."""
        last, self._last = self._last, (t, x, y, vx, vy)
        if self.riding_since is None:
            if self._blend is None:
                return x, y
            t_end, (cx, cy) = self._blend       # what the dead reckoning was off, fading out
            k = 1.0 - (t - t_end) / self.blend_s
            if k <= 0.0:
                self._blend = None
                return x, y
            return x - k * cx, y - k * cy
        if last is not None and 0.0 < t - last[0] <= 0.5:
            dt = t - last[0]
            self._dead = (self._dead[0] + 0.5 * (vx + last[3]) * dt,
                          self._dead[1] + 0.5 * (vy + last[4]) * dt)
        apart = math.hypot(x - self._dead[0], y - self._dead[1])
        self._apart = max(self._apart, apart)
        if self._back and (apart <= self.settle or t - self._back_at >= self.back_wait):
            # the estimate has followed the receiver back (or had back_wait to): handed back,
            # what the dead reckoning drifted meanwhile faded out over blend_s, not stepped
            self._blend = (t, (x - self._dead[0], y - self._dead[1]))
            dead = self._dead
            self._end()
            return dead
        if t - self.riding_since >= self.confirm and self._apart <= max(self.settle,
                                                                         0.25 * self._size):
            # the estimate never followed the receiver's step: nothing to ride through
            self.jumps, self.false_alarms = self.jumps - 1, self.false_alarms + 1
            self._end()
            self._history.clear()      # the receiver's new place is its baseline
            return x, y
        return self._dead

    def _end(self) -> None:
        self.riding_since, self._pending, self._back = None, None, False

    def overdue(self, t: float) -> bool:
        """Riding through for longer than ``max_ride`` at vehicle time ``t``."""
        return self.riding_since is not None and t - self.riding_since > self.max_ride

    def forget(self) -> None:
        """Start again from the estimate (after a hold, a gap): no ride, no baseline."""
        self._end()
        self._blend = None
        self._history.clear()
        self._last = self._before = None
