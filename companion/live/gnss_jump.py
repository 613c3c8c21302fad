"""Jumps of the receiver that its own class does not admit: multipath moving a "fixed" solution.

ArduPilot's EKF takes any GNSS position as at least 0.5 m uncertain, so a receiver that says
"RTK fixed" while multipath moves it by decimetres is followed: LOCAL_POSITION_NED slides over
a second or two to the jumped position, without a flag (docs/gnss.md). The slide is too slow to
tell from driving in one sample; the receiver's own step is not. :class:`JumpGuard`:

* compares each new fix (GPS_RAW_INT's position, a step between two fixes) with what the
  rover's own motion explains (the estimate's velocity over the fixes' interval); a step larger
  than ``threshold`` beyond it is a jump, and the jumps add up to the receiver's offset;
* while that offset is more than ``threshold``, **rides through**: the position the controller
  gets is dead-reckoned from the last position before the jump with the estimate's velocity,
  not the estimate's sliding position;
* once the receiver has stepped back (its offset under ``threshold``) and the estimate has
  come back to the dead-reckoned position (within ``settle``), hands the estimate back; and
  when the estimate has not left the dead-reckoned position by ``confirm`` s, the step was not
  one the estimator followed (a one-off fix): the estimate is handed back at once;
* after ``max_ride`` s of riding it gives up (:meth:`overdue`): the runner then holds the
  rover, and starts again from the estimate.

A receiver whose class claims metres (``h_acc`` above ``max_h_acc``: plain GPS) is not
judged: its wander is not a jump, and nothing is ridden through. Pure: no I/O, no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

EARTH = 6378137.0                      # m: only differences of nearby fixes are taken


@dataclass
class JumpGuard:
    """Ride through receiver jumps (see the module docstring)."""

    threshold: float = 0.10            # m a fix may step beyond the rover's own motion
    settle: float = 0.03               # m: the estimate back on the dead-reckoned position
    max_ride: float = 8.0              # s of riding through before giving up
    max_h_acc: float = 0.2             # m: a receiver claiming more is not judged
    max_fix_gap: float = 0.5           # s: fixes further apart are not compared
    jumps: int = 0                     # jumps ridden through
    _fix: tuple[float, float, float] | None = None    # t (s), lat, lon (degrees) of the last
    _offset: tuple[float, float] = (0.0, 0.0)          # the receiver's jumps summed (n, e; m)
    _velocity: tuple[float, float] = (0.0, 0.0)        # the estimate's latest (vx, vy)
    _fix_velocity: tuple[float, float] = (0.0, 0.0)    # ... when the last fix came
    _apart: float = 0.0                # m: the most the estimate left the dead reckoning
    confirm: float = 1.5               # s: an estimate that has not left it by then: no jump
    false_alarms: int = 0
    _last: tuple[float, float, float, float, float] | None = None   # t, x, y, vx, vy
    riding_since: float | None = None  # vehicle s the ride began (None: not riding)
    _dead: tuple[float, float] = (0.0, 0.0)            # the dead-reckoned position
    _back: bool = False                # the receiver has stepped back

    def fix(self, t: float, lat_e7: int, lon_e7: int, h_acc: float | None) -> str | None:
        """A new GPS_RAW_INT fix at ``t`` (s, the receiver's): a line when a ride begins or
        the receiver steps back, else None."""
        lat, lon = lat_e7 * 1e-7, lon_e7 * 1e-7
        last, self._fix = self._fix, (t, lat, lon)
        v_then, self._fix_velocity = self._fix_velocity, self._velocity
        if last is None or (lat_e7 == 0 and lon_e7 == 0):
            return None
        dt = t - last[0]
        if not 0.0 < dt <= self.max_fix_gap or (h_acc is not None and h_acc > self.max_h_acc):
            return None
        north = math.radians(lat - last[1]) * EARTH
        east = math.radians(lon - last[2]) * EARTH * math.cos(math.radians(lat))
        # the motion over the interval: the estimate's velocity at both fixes (trapezoid), so
        # a rover speeding up or turning leaves no residual
        vx, vy = 0.5 * (self._velocity[0] + v_then[0]), 0.5 * (self._velocity[1] + v_then[1])
        rn, re = north - vx * dt, east - vy * dt
        # a fix's time and the velocity's differ by up to an interval: the change of velocity
        # over it is doubt, not a jump (a rover starting hard)
        doubt = 0.5 * math.hypot(self._velocity[0] - v_then[0], self._velocity[1] - v_then[1]) * dt
        if math.hypot(rn, re) <= self.threshold + doubt:
            return None
        on, oe = self._offset
        self._offset = (on + rn, oe + re)
        size = math.hypot(*self._offset)
        if self.riding_since is None and size > self.threshold and self._last is not None:
            self.riding_since, self._back, self.jumps = self._last[0], False, self.jumps + 1
            self._dead, self._apart = (self._last[1], self._last[2]), 0.0
            return (f"the receiver jumped {math.hypot(rn, re):.2f} m more than the rover's "
                    f"motion explains: riding through on the rover's own motion (at most "
                    f"{self.max_ride:g} s)")
        if self.riding_since is not None and size <= self.threshold:
            self._offset, self._back = (0.0, 0.0), True
            return "the receiver stepped back: rejoining the estimate once it has followed"
        return None

    def position(self, t: float, x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        """An accepted LOCAL_POSITION_NED: the position to steer by (the estimate's, or the
        dead-reckoned one while riding through)."""
        last, self._last, self._velocity = self._last, (t, x, y, vx, vy), (vx, vy)
        if self.riding_since is None:
            return x, y
        if last is not None and 0.0 < t - last[0] <= self.max_fix_gap:
            dt = t - last[0]
            self._dead = (self._dead[0] + 0.5 * (vx + last[3]) * dt,
                          self._dead[1] + 0.5 * (vy + last[4]) * dt)
        apart = math.hypot(x - self._dead[0], y - self._dead[1])
        self._apart = max(self._apart, apart)
        if self._back and apart <= self.settle:
            self.riding_since = None
            return x, y
        if t - self.riding_since >= self.confirm and self._apart <= self.settle:
            # the estimate never followed the receiver's step: nothing to ride through
            self.riding_since, self._offset, self.jumps = None, (0.0, 0.0), self.jumps - 1
            self.false_alarms += 1
            return x, y
        return self._dead

    def overdue(self, t: float) -> bool:
        """Riding through for longer than ``max_ride`` at vehicle time ``t``."""
        return self.riding_since is not None and t - self.riding_since > self.max_ride

    def forget(self) -> None:
        """Start again from the estimate (after a hold, a gap): no ride, no offset."""
        self.riding_since, self._offset, self._back = None, (0.0, 0.0), False
        self._fix = self._last = None
