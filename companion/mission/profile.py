"""What a reference trajectory asks of the vehicle: distance, peak speed, peak turn rate.

The turn rate is the rate of the reference's heading, d/dt atan2(vy, vx) = (vx ay - vy ax)/|v|^2,
which a rover following the reference exactly must turn at. It is measured only where the
reference moves at least ``STANDSTILL`` m/s: at a standstill the heading is undefined and the
rover may pivot in place.

Peaks come from the trajectory's own exact ``peaks()`` when it has one (circle, polyline), else
from dense sampling over one lap (periodic kinds) or over the motion (open kinds).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..core.limits import Limits

STANDSTILL = 0.05          # m/s
MAX_SAMPLES = 20000        # per check: keeps `mission check` and the loader quick
SAMPLE_STEP = 0.01         # s, finest sampling


@dataclass(frozen=True)
class MotionProfile:
    length: float          # m the reference travels over the mission
    peak_speed: float      # m/s
    peak_turn_rate: float  # rad/s
    peak_speed_t: float    # s, when the peak speed happens (first time)
    peak_turn_t: float     # s


def turn_rate(vx: float, vy: float, ax: float, ay: float) -> float:
    speed2 = vx * vx + vy * vy
    if speed2 < STANDSTILL * STANDSTILL:
        return 0.0
    return (vx * ay - vy * ax) / speed2


def measure(trajectory, duration: float, period: float | None = None,
            motion_end: float | None = None) -> MotionProfile:
    """Sample ``trajectory`` over [0, duration] (one lap of ``period`` is enough for the peaks)."""
    window = duration
    if period is not None:
        window = min(window, period)
    if motion_end is not None:
        window = min(window, motion_end)
    window = max(window, 0.0)
    n = max(2, min(MAX_SAMPLES, int(math.ceil(window / SAMPLE_STEP)) + 1))
    dt = window / (n - 1)
    peak_v = peak_w = 0.0
    t_v = t_w = 0.0
    dist = 0.0
    prev_speed = None
    for k in range(n):
        t = k * dt
        r = trajectory.sample(t)
        speed = math.hypot(r.vx, r.vy)
        w = abs(turn_rate(r.vx, r.vy, r.ax, r.ay))
        if not (math.isfinite(speed) and math.isfinite(w) and math.isfinite(r.x)
                and math.isfinite(r.y)):
            raise ValueError(f"the trajectory is not finite at t = {t:g} s")
        if speed > peak_v:
            peak_v, t_v = speed, t
        if w > peak_w:
            peak_w, t_w = w, t
        if prev_speed is not None:
            dist += 0.5 * (speed + prev_speed) * dt   # trapezoid rule
        prev_speed = speed
    # Scale the sampled distance to the whole mission: whole laps, or nothing after the motion.
    if period is not None and window > 0 and duration > window:
        dist *= duration / window
    exact = getattr(trajectory, "peaks", None)
    if exact is not None:
        peak_v, peak_w = exact()
    return MotionProfile(dist, peak_v, peak_w, t_v, t_w)


def limit_problem(profile: MotionProfile, limits: Limits, where=None) -> tuple[str, str] | None:
    """``(key, message)`` for the first limit the profile exceeds, or None.

    ``where(t)`` may describe the place in the trajectory at time t (waypoint pair).
    """
    tol = 1e-9
    for key, peak, limit, t, unit in (
            ("max_speed", profile.peak_speed, limits.max_speed, profile.peak_speed_t, "m/s"),
            ("max_yaw_rate", profile.peak_turn_rate, limits.max_yaw_rate, profile.peak_turn_t,
             "rad/s")):
        if peak > limit * (1.0 + tol):
            place = f" {where(t)}" if where is not None else f" at t = {t:.3g} s"
            what = "speed" if key == "max_speed" else "turn rate"
            return key, (f"needs a {what} of {peak:.3g} {unit}{place}, more than "
                         f"limits.{key} = {limit:g}")
    return None
