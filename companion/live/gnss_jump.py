"""Jumps of the receiver that its own class does not admit: multipath moving a "fixed" solution.

ArduPilot's EKF takes any GNSS position as at least 0.5 m uncertain, so a receiver that says
"RTK fixed" while multipath moves it by decimetres is followed: LOCAL_POSITION_NED slides over
a second or two to the jumped position, and its velocity leans the same way (measured: 0.05-0.08
m/s for a 0.25 m jump, docs/gnss.md), so dead reckoning on it follows the jump too. The
receiver itself is the better witness. :class:`JumpGuard`:

* relates each new fix (GPS_RAW_INT's position, arriving with the estimate's latest sample) to
  the estimate: receiver = estimate + ``c`` - ``lag`` x velocity, ``c`` the frames' offset and
  ``lag`` the fix's age on arrival, fitted over the last ``fit_fixes`` fixes (least squares);
  its residual is the receiver's error against the estimate, centimetres in good times;
* two fixes in a row with a residual over ``threshold``, within half of it of each other, are a
  jump ``J`` (one alone is a fix that arrived late); then it **rides through**: the controller steers by
  the receiver's own last fix less ``J``, moved on by the estimate's velocity since the fix was
  taken (a tenth of a second or so of it, not the estimate's sliding position);
* when the receiver steps back by about ``J`` (two fixes in a row), the jump is over; the ride
  goes on by the receiver alone until the estimate agrees with it again (residual under
  ``settle`` for two fixes) or ``back_wait`` s have passed, and the estimate is handed back,
  any difference faded out over ``blend_s`` (no step);
* after ``max_ride`` s of riding it gives up (:meth:`overdue`): the runner then holds the rover,
  and starts again from the estimate.

A receiver claiming more than ``max_h_acc`` (plain GPS) is not judged: its wander is not a jump.
Pure: no I/O, no clock.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from itertools import pairwise

from ..mission.geo import ne_from_latlon

Vec = tuple[float, float]


class LagWindow:
    """The last ``size`` pairs (d_n, d_e, v_n, v_e) of receiver - estimate and the estimate's
    velocity, and the least-squares fit d = c - lag x v over them (one lag for both axes).

    Kept as running sums, so a fix costs the same whatever the window (the loop takes one at
    10 Hz beside a 40 Hz control cycle); the sums are rebuilt from the pairs each time the
    window has turned over, so rounding does not build up over a long run."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._pairs: deque[tuple[float, float, float, float]] = deque()
        self._sums = [0.0] * 8          # dn, de, vn, ve, dn vn, de ve, vn^2, ve^2
        self._added = 0

    def __len__(self) -> int:
        return len(self._pairs)

    def add(self, dn: float, de: float, vn: float, ve: float) -> None:
        self._pairs.append((dn, de, vn, ve))
        self._count(dn, de, vn, ve, 1.0)
        if len(self._pairs) > self.size:
            self._count(*self._pairs.popleft(), -1.0)
        self._added += 1
        if self._added % self.size == 0:
            self._sums = [0.0] * 8
            for pair in self._pairs:
                self._count(*pair, 1.0)

    def _count(self, dn: float, de: float, vn: float, ve: float, sign: float) -> None:
        s = self._sums
        for i, v in enumerate((dn, de, vn, ve, dn * vn, de * ve, vn * vn, ve * ve)):
            s[i] += sign * v

    def lag(self) -> float | None:
        """The least-squares lag, or None when the velocities hardly vary (no lag to tell)."""
        k = len(self._pairs)
        dn, de, vn, ve, dnvn, deve, vn2, ve2 = self._sums
        den = (vn2 - vn * vn / k) + (ve2 - ve * ve / k)
        if den <= 1e-6:
            return None
        return -((dnvn - dn * vn / k) + (deve - de * ve / k)) / den

    def offset(self, lag: float) -> Vec:
        """(c_n, c_e): the offset that, with ``lag``, fits the pairs best (their means)."""
        k = len(self._pairs)
        dn, de, vn, ve = self._sums[:4]
        return (dn + lag * vn) / k, (de + lag * ve) / k


@dataclass
class JumpGuard:
    """Ride through receiver jumps (see the module docstring)."""

    threshold: float = 0.15            # m: a fix's residual beyond this is off
    settle: float = 0.06               # m: the estimate agrees with the receiver again (the
    #                                    residual's own scatter on SITL under load: 2-5 cm)
    max_ride: float = 10.0             # s of riding through before giving up
    max_h_acc: float = 0.2             # m: a receiver claiming more is not judged
    back_wait: float = 8.0             # s after the jump ends before the estimate is handed back
    blend_s: float = 2.0               # s a difference at hand-back fades out over
    fit_fixes: int = 60                # fixes the receiver-estimate relation is fitted over
    min_fit_fixes: int = 20
    jumps: int = 0                     # jumps ridden through
    riding_since: float | None = None  # vehicle s the ride began (None: not riding)
    _origin: Vec | None = None         # lat, lon (degrees) of the first fix
    _last_fix: tuple[int, int] | None = None
    _pairs: LagWindow = field(default_factory=lambda: LagWindow(60))  # receiver - estimate
    _track: deque = field(default_factory=lambda: deque(maxlen=80))   # (t, x, y, vx, vy): estimate
    _last: tuple[float, float, float, float, float] | None = None    # t, x, y, vx, vy
    _fit: tuple[float, float, float] | None = None     # c_n, c_e, lag
    _pending: Vec | None = None        # one fix off
    _jump: Vec = (0.0, 0.0)            # J
    _fix_at: tuple[float, float, float] | None = None  # the ride's fix: taken at (s), n, e
    _ended_at: float | None = None     # s the receiver stepped back (None: still jumped)
    _calm: int = 0                     # fixes in a row agreeing with the estimate after it
    _blend: tuple[float, Vec] | None = None            # (s, offset) handing back
    _unjudged: bool = False            # the last fix claimed too much to be judged (float)

    def __post_init__(self) -> None:
        self._pairs = LagWindow(self.fit_fixes)

    # --- the receiver ---------------------------------------------------------------------------
    def fix(self, lat_e7: int, lon_e7: int, h_acc: float | None) -> str | None:
        """A GPS_RAW_INT: a line when a ride begins or the jump ends, else None."""
        if (lat_e7 == 0 and lon_e7 == 0) or (lat_e7, lon_e7) == self._last_fix:
            return None                 # no fix, or the same fix again
        self._last_fix = (lat_e7, lon_e7)
        if self._last is None:
            return None
        if h_acc is not None and h_acc > self.max_h_acc:
            self._end_ride()              # float, plain GPS: not judged, nor steered by
            self._unjudged = True
            return None
        lat, lon = lat_e7 * 1e-7, lon_e7 * 1e-7
        if self._origin is None:
            self._origin = (lat, lon)
        n, e = ne_from_latlon(lat, lon, self._origin)   # (as ArduPilot converts them)
        t, x, y, vx, vy = self._last
        if self._unjudged:
            self._unjudged = False
            if self._fit is not None and self._residual(t, n, e) is not None:
                # back to its class after float: the receiver is right and the estimate, which
                # followed the float, re-converges for seconds: steer by the receiver till then
                self._receiver_mode(t, n, e)
                return ("the receiver is back in its class: steering by it until the estimate "
                        "agrees again")
        if self.riding_since is None:
            return self._watch(t, n, e, x, y, vx, vy)
        return self._riding(t, n, e)

    def _residual(self, t: float, n: float, e: float) -> tuple[Vec, float] | None:
        """The fix's residual against the estimate where the fit says it was taken, and when."""
        if self._fit is None:
            return None
        cn, ce, lag = self._fit
        then = self._estimate_at(t - lag)
        if then is None:
            return None
        return (n - cn - then[0], e - ce - then[1]), t - lag

    def _watch(self, t: float, n: float, e: float, x: float, y: float, vx: float,
               vy: float) -> str | None:
        got = self._residual(t, n, e)
        off = got[0] if got is not None and math.hypot(*got[0]) > self.threshold else None
        pending, self._pending = self._pending, off
        if off is None:
            self._pairs.add(n - x, e - y, vx, vy)
            self._refit()
            return None
        if pending is None or \
                math.hypot(off[0] - pending[0], off[1] - pending[1]) > 0.5 * self.threshold:
            return None                 # one fix off: a late one, or the first of a jump
        assert got is not None
        self._pending, self.jumps, self.riding_since = None, self.jumps + 1, self._last[0]  # type: ignore[index]
        self._jump = pending            # the first: the estimate had hardly slid yet
        self._ended_at, self._calm, self._blend = None, 0, None
        self._fix_at = (got[1], n - self._fit[0] - self._jump[0],      # type: ignore[index]
                        e - self._fit[1] - self._jump[1])               # type: ignore[index]
        return (f"the receiver jumped {math.hypot(*self._jump):.2f} m, still claiming its "
                f"class: riding through on the receiver less the jump (at most "
                f"{self.max_ride:g} s)")

    def _receiver_mode(self, t: float, n: float, e: float) -> None:
        got = self._residual(t, n, e)
        assert got is not None and self._fit is not None
        self.riding_since = self._ended_at = t
        self._jump, self._calm, self._blend, self._pending = (0.0, 0.0), 0, None, None
        self._fix_at = (got[1], n - self._fit[0], e - self._fit[1])

    def steering(self) -> bool:
        """Steering by the receiver now (a ride, or after float until the estimate agrees)."""
        return self.riding_since is not None

    def _riding(self, t: float, n: float, e: float) -> str | None:
        got = self._residual(t, n, e)
        if got is None:
            return None
        (rn, re), taken = got
        cn, ce, _ = self._fit  # type: ignore[misc]
        if self._ended_at is None:
            # still jumped: the ride goes on from this fix less J, until two fixes in a row
            # sit where the ride is (J back); the first of them leaves the ride's fix as it was
            here = self._steer_at(taken)
            if here is not None and math.hypot(n - cn - here[0], e - ce - here[1]) <= self.threshold:
                self._calm += 1
                if self._calm >= 2:
                    self._ended_at, self._calm = self._last[0], 0  # type: ignore[index]
                    self._fix_at = (taken, n - cn, e - ce)
                    return "the receiver is back: rejoining the estimate once it agrees again"
                return None
            self._calm = 0
            self._fix_at = (taken, n - cn - self._jump[0], e - ce - self._jump[1])
            return None
        # the jump is over: on the receiver alone until the estimate agrees with it again
        self._fix_at = (taken, n - cn, e - ce)
        self._calm = self._calm + 1 if math.hypot(rn, re) <= self.settle else 0
        return None

    def _refit(self) -> None:
        """receiver - estimate = c - lag x velocity, least squares over the pairs kept."""
        if len(self._pairs) < self.min_fit_fixes:
            return
        lag = self._pairs.lag()
        if lag is None:               # no spread of velocity to tell a lag from an offset by
            lag = self._fit[2] if self._fit else 0.0
        # (negative: the fix is younger than the estimate's sample it arrived with)
        lag = min(max(lag, -0.5), 0.5)
        self._fit = (*self._pairs.offset(lag), lag)

    # --- the estimate ---------------------------------------------------------------------------
    def _estimate_at(self, when: float) -> Vec | None:
        """The estimate's position at ``when`` (linear between its samples)."""
        track = self._track
        if not track or when < track[0][0]:
            return None
        for i in range(len(track) - 1, 0, -1):
            t1, x1, y1 = track[i][:3]
            t0, x0, y0 = track[i - 1][:3]
            if t0 <= when <= t1:
                a = (when - t0) / (t1 - t0) if t1 > t0 else 0.0
                return x0 + a * (x1 - x0), y0 + a * (y1 - y0)
        t1, x1, y1, vx1, vy1 = track[-1]       # after the last sample: carried on its velocity
        return (x1 + vx1 * (when - t1), y1 + vy1 * (when - t1)) if when >= t1 else None

    def _moved(self, since: float, now: float) -> Vec | None:
        """How far the estimate's velocity carried the rover from ``since`` to ``now`` (its
        velocity, not its position: the position slides after the receiver, the velocity
        hardly)."""
        track = self._track
        if not track or min(since, now) < track[0][0]:
            return None
        if since > now:                          # a fix younger than the sample: back along it
            back = self._moved(now, since)
            return None if back is None else (-back[0], -back[1])
        mn = me = 0.0
        t_end, _, _, vx_end, vy_end = track[-1]
        if now > t_end:                          # beyond the last sample: on its velocity
            mn, me = vx_end * (now - max(t_end, since)), vy_end * (now - max(t_end, since))
        for (t0, _, _, vx0, vy0), (t1, _, _, vx1, vy1) in pairwise(track):
            a, b = max(t0, since), min(t1, now)
            if b > a:
                mn += 0.5 * (vx0 + vx1) * (b - a)
                me += 0.5 * (vy0 + vy1) * (b - a)
        return mn, me

    def _steer_at(self, now: float) -> Vec | None:
        """The ride's position at ``now``: the ride's fix, moved on by the rover's motion."""
        if self._fix_at is None:
            return None
        taken, n, e = self._fix_at
        moved = self._moved(taken, now)
        if moved is None:
            return None
        return n + moved[0], e + moved[1]

    def position(self, t: float, x: float, y: float, vx: float, vy: float) -> Vec:
        """An accepted LOCAL_POSITION_NED: the position to steer by (the estimate's, or the
        receiver's through a jump)."""
        self._last = (t, x, y, vx, vy)
        self._track.append((t, x, y, vx, vy))
        if self.riding_since is None:
            if self._blend is None:
                return x, y
            t_end, (cx, cy) = self._blend       # the difference at hand-back, fading out
            k = 1.0 - (t - t_end) / self.blend_s
            if k <= 0.0:
                self._blend = None
                return x, y
            return x - k * cx, y - k * cy
        steer = self._steer_at(t)
        if steer is None:
            return x, y
        if self._ended_at is not None and (self._calm >= 2 or t - self._ended_at >= self.back_wait):
            self._blend = (t, (x - steer[0], y - steer[1]))
            self.riding_since = None
        return steer

    def overdue(self, t: float) -> bool:
        """Still jumped after ``max_ride`` s of riding through, at vehicle time ``t``."""
        return (self.riding_since is not None and self._ended_at is None
                and t - self.riding_since > self.max_ride)

    def _end_ride(self) -> None:
        self.riding_since, self._pending, self._blend, self._fix_at = None, None, None, None

    def forget(self) -> None:
        """Start again from the estimate (after a gap, or a hold's re-engagement): no ride, no
        history of the estimate; the receiver's relation to it (the frames, the lag) is kept."""
        self._end_ride()
        self._track.clear()
