"""Can this vehicle follow this reference? What ``companion mission check --vehicle FILE`` says.

A reference that asks for more than the vehicle can do is not tracked, whatever the controller:
an Ackermann rover asked to turn tighter than its minimum turning radius falls behind on the
bend and, if the law then points u_p backwards, drives a loop; one asked to slow down faster
than its deceleration limit overshoots. The checks sample the reference (its analytic velocity
and acceleration) and compare, per instant, with the vehicle file
(:class:`companion.sim.plant.RoverParams`):

* radius of curvature |v|^3 / |v x a| below ``min_turn_radius`` (only while the reference moves);
* speed above ``max_speed``;
* d|v|/dt = v . a / |v| below -decel (slowing faster than it can) or above ``max_accel``;
* turn rate |v x a| / |v|^2 above ``max_yaw_rate``;
* lateral acceleration |v x a| / |v| above ``max_lat_accel`` (ArduPilot's ``ATC_TURN_MAX_G``:
  its turn-rate target is clamped to it over max(|v|, 1 m/s), a car's and a skid-steer's alike).

Each kind is reported once: its worst instant, and how long in all the reference is beyond.
Pure: a trajectory and parameters in, lines out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..sim.plant import LAT_ACCEL_MIN_SPEED, RoverParams

MOVING = 0.05          # m/s: below this the reference stands still (no course, no curvature)
STEP = 0.02            # s between samples


@dataclass(frozen=True)
class Problem:
    kind: str          # radius | speed | decel | accel | turn_rate | lat_accel
    worst_t: float     # s of mission time
    worst: float       # the reference's value there (m, m/s, m/s^2, rad/s)
    limit: float       # the vehicle's
    seconds: float     # how long in all the reference is beyond the limit

    def describe(self) -> str:
        what = {
            "radius": ("turns tighter than the minimum turning radius", "radius {v:.2f} m", "m"),
            "speed": ("is faster than the vehicle's top speed", "{v:.2f} m/s", "m/s"),
            "decel": ("slows down faster than the vehicle can", "{v:.2f} m/s^2", "m/s^2"),
            "accel": ("speeds up faster than the vehicle can", "{v:.2f} m/s^2", "m/s^2"),
            "turn_rate": ("turns faster than the vehicle's turn-rate limit", "{v:.2f} rad/s",
                          "rad/s"),
            "lat_accel": ("turns harder than the vehicle's lateral-acceleration limit",
                          "{v:.2f} m/s^2", "m/s^2"),
        }[self.kind]
        return (f"the reference {what[0]}: {what[1].format(v=self.worst)} at t = "
                f"{self.worst_t:.1f} s against {self.limit:.3g} {what[2]} "
                f"({self.seconds:.1f} s beyond in all)")


def check(trajectory, duration: float, vehicle: RoverParams, step: float = STEP
          ) -> list[Problem]:
    """The reference's problems for ``vehicle`` over ``[0, duration]`` (empty: followable)."""
    found: dict[str, list[float]] = {}          # kind -> [worst_t, worst, limit, seconds]

    def note(kind: str, t: float, value: float, limit: float, worse: bool) -> None:
        entry = found.get(kind)
        if entry is None:
            found[kind] = [t, value, limit, step]
            return
        entry[3] += step
        if worse:
            entry[0], entry[1] = t, value

    r_min = float(vehicle.min_turn_radius)
    top, accel, decel = float(vehicle.max_speed), float(vehicle.max_accel), float(vehicle.decel)
    top_rate = float(vehicle.max_yaw_rate)
    lateral = float(vehicle.max_lat_accel)
    n = int(math.floor(duration / step)) + 1
    for k in range(n):
        t = k * step
        ref = trajectory.sample(t)
        vx, vy, ax, ay = (float(v) for v in (ref.vx, ref.vy, ref.ax, ref.ay))
        speed = math.hypot(vx, vy)
        if speed > top + 1e-9:
            note("speed", t, speed, top, speed > found.get("speed", [0, -1])[1])
        if speed < MOVING:
            continue
        cross = abs(vx * ay - vy * ax)
        along = (vx * ax + vy * ay) / speed
        if r_min > 0 and cross > 1e-12:
            radius = speed ** 3 / cross
            if radius < r_min:
                note("radius", t, radius, r_min, radius < found.get("radius", [0, math.inf])[1])
        if along < -decel - 1e-9:
            note("decel", t, -along, decel, -along > found.get("decel", [0, -1])[1])
        if along > accel + 1e-9:
            note("accel", t, along, accel, along > found.get("accel", [0, -1])[1])
        rate = cross / (speed * speed)
        if rate > top_rate + 1e-9:
            note("turn_rate", t, rate, top_rate, rate > found.get("turn_rate", [0, -1])[1])
        # the turn rate allowed is a / max(|v|, 1 m/s): below 1 m/s less than a of lateral
        lat, lat_limit = cross / speed, lateral * speed / max(speed, LAT_ACCEL_MIN_SPEED)
        if lat > lat_limit + 1e-9:
            note("lat_accel", t, lat, lat_limit, lat > found.get("lat_accel", [0, -1])[1])
    order = ("radius", "decel", "speed", "accel", "turn_rate", "lat_accel")
    return [Problem(kind, *found[kind]) for kind in order if kind in found]
