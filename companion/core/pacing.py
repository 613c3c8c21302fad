"""The reference's pace: a mission clock that runs slower than the vehicle's, or starts again
gently after the rover has stood still.

The trajectory is a function of mission time, p_ref(tau). Flying it on a clock tau(t) whose
rate r(t) = d tau / dt differs from 1 changes the reference's derivatives, which the PZC law's
feed-forward uses (the paper's Eq. 12 takes p_ref's velocity and acceleration):

    d p_ref / dt   = r p_ref'(tau)
    d2 p_ref / dt2 = r^2 p_ref''(tau) + r' p_ref'(tau)

:func:`paced` applies that to a :class:`~companion.core.signals.Reference`. :func:`ramp` is a
clock whose rate grows linearly from 0 to 1 over ``ramp_s`` (a rover at rest rejoining a path
that moves at full speed: the reference accelerates at its speed / ``ramp_s`` instead of
leaping away). :func:`rejoin_time` finds where on the path a stopped rover stands, at or after
the held mission time: the distance it braked is part of the path it drove, not a lead for it
to drive back.

Pure: no I/O, no clock.
"""

from __future__ import annotations

import math

from .signals import Reference
from .trajectory import Trajectory

# mission s after the held time searched for the stopped rover's place (a car in HOLD coasts
# 3 m and more: docs/gnss.md)
REJOIN_HORIZON = 10.0
REJOIN_NEAR = 0.5      # m: a rover further from the path than this is not on it (a car
#                        coasting in HOLD ends 0.4 m off it: docs/gnss.md)


def paced(ref: Reference, rate: float, rate_dot: float = 0.0) -> Reference:
    """``ref`` flown on a clock running at ``rate`` (changing at ``rate_dot`` per s)."""
    r2 = rate * rate
    return Reference(ref.x, ref.y, ref.vx * rate, ref.vy * rate,
                     ref.ax * r2 + ref.vx * rate_dot, ref.ay * r2 + ref.vy * rate_dot)


def ramp(elapsed: float, ramp_s: float) -> tuple[float, float, float]:
    """(mission s advanced, rate, rate's derivative) ``elapsed`` vehicle s into a segment whose
    clock rate ramps linearly from 0 to 1 over ``ramp_s`` (0: no ramp, the rate is 1)."""
    if ramp_s <= 0.0 or elapsed >= ramp_s:
        return elapsed - 0.5 * max(ramp_s, 0.0), 1.0, 0.0
    if elapsed <= 0.0:
        return 0.0, 0.0, 1.0 / ramp_s
    return 0.5 * elapsed * elapsed / ramp_s, elapsed / ramp_s, 1.0 / ramp_s


def rejoin_time(trajectory: Trajectory, held: float, x: float, y: float, horizon: float,
                step: float = 0.02, near: float = REJOIN_NEAR) -> float:
    """The mission time in [held, held + horizon] whose reference point is nearest (x, y): the
    first (so a path that comes back on itself is not skipped round), to ``step`` s. Only a rover
    within ``near`` m of that point stands on the path: one further off (still on its way to the
    path) rejoins at ``held``, so no part of the path is skipped."""
    best_t, best_d = held, math.inf
    n = max(1, int(math.ceil(horizon / step)))
    for k in range(n + 1):
        t = held + k * step
        ref = trajectory.sample(t)
        d = math.hypot(ref.x - x, ref.y - y)
        if d < best_d - 1e-9:
            best_t, best_d = t, d
        elif d > best_d + 0.5:
            break       # walking away from the rover: the nearest point is behind
    return best_t if best_d <= near else held


def rejoin(trajectory: Trajectory, held: float, x: float, y: float, duration: float,
           accel: float, rate: float = 1.0) -> tuple[float, float]:
    """Where a rover standing at (x, y) after a stop takes the path up again: (the mission
    time of its place, :func:`rejoin_time`, no later than ``duration``; the seconds its ramp to
    the reference's speed there, times ``rate``, takes at ``accel``). The live loop's rule, and
    the one ``companion plot`` replays a .tlog's mission clock with."""
    time = min(rejoin_time(trajectory, held, x, y, REJOIN_HORIZON), duration)
    ref = trajectory.sample(time)
    return time, ramp_seconds(math.hypot(ref.vx, ref.vy) * rate, accel)


def ramp_seconds(speed: float, accel: float) -> float:
    """How long a ramp from rest to ``speed`` (m/s) takes at ``accel`` (m/s^2; 0 or less: none)."""
    if not (accel > 0.0 and math.isfinite(speed)) or speed <= 0.0:
        return 0.0
    return speed / accel           # a linear rate: the reference accelerates at speed / ramp_s
