"""From the position-loop output u_p to a command within the vehicle's limits.

Shared by every tracker (PZC and the PID baseline), so the speed law, the clamps and the
anti-windup rule are written once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .ops import Ops
from .signals import Command, Num

SPEED_LAWS = ("projected", "paper")


@dataclass(frozen=True)
class Limits:
    """Command limits: |v_ref| <= max_speed (m/s), |omega_ref| <= max_yaw_rate (rad/s), and for
    a car driven by speed / turn-rate setpoints (ArduPilot's Ackermann rover) a command no
    tighter than its turning radius: |omega_ref| <= |v_ref| / min_turn_radius (m; 0: none).

    Why the car's: ArduPilot's turn-rate target is not held to what the steering can give at the
    speed of the moment, so a setpoint above |v| / R leaves the steering at full lock while the
    rate loop's integrator winds up, and the target, accelerating at ATC_STR_ACC_MAX from far
    above, takes most of a second to come back through the turn rate flown when the setpoint
    reverses (measured on SITL's car: docs/calibrate-and-identify.md, "What the companion does
    for a car"). Held to the command's own speed: the one the vehicle is asked to fly."""

    max_speed: float = math.inf
    max_yaw_rate: float = math.inf
    min_turn_radius: float = 0.0

    def __post_init__(self) -> None:
        for name in ("max_speed", "max_yaw_rate"):
            value = getattr(self, name)
            if not value > 0:
                raise ValueError(f"{name} must be > 0, not {value!r}")
        if not (math.isfinite(self.min_turn_radius) and self.min_turn_radius >= 0):
            raise ValueError(f"min_turn_radius must be >= 0, not {self.min_turn_radius!r}")


# The companion's ceiling for a vehicle whose limits nobody gave: above what the paper's ellipse
# needs at 0.12 Hz (peak 4.8 m/s), and a turn rate a 40 Hz yaw loop can use without chattering.
DEFAULT_LIMITS = Limits(max_speed=6.0, max_yaw_rate=6.0)


def speed_from_up(m: Ops, speed_law: str, norm_up: Num, heading_error: Num) -> Num:
    """v_ref from u_p: the paper's |u_p| (eq. 20) or its projection on the heading (default).

    ``norm_up`` is |u_p| and ``heading_error`` is phi_ref - phi with phi_ref = atan2(u_y, u_x), so
    the projection u_x cos(phi) + u_y sin(phi) equals |u_p| cos(heading_error): one cosine instead
    of two trig calls. See :mod:`companion.core.pzc` for why the projection is the default.
    """
    if speed_law == "paper":
        return norm_up
    return norm_up * m.cos(heading_error)


def yaw_rate_limit(m: Ops, lim: Limits, speed: Num) -> Num:
    """The turn-rate limit of a command at ``speed`` (the clamped speed: what the vehicle is
    asked to drive): ``max_yaw_rate``, and for a car no more than ``|speed| / min_turn_radius``."""
    if not lim.min_turn_radius:
        return lim.max_yaw_rate
    return m.minimum(lim.max_yaw_rate, abs(speed) / lim.min_turn_radius)


def clip_yaw_rate(m: Ops, lim: Limits, speed: Num, yaw_rate: Num) -> Num:
    """``yaw_rate`` within :func:`yaw_rate_limit` at ``speed``: what a stage after the law
    (lead, prediction, overshoot cancel) applies again once it has changed the speed sent."""
    top = yaw_rate_limit(m, lim, speed)
    return m.clip(yaw_rate, -top, top)


def clamp(m: Ops, lim: Limits, speed: Num, yaw_rate: Num, ux: Num, uy: Num,
          norm_up: Num) -> tuple[Command, Num, Num]:
    """Clamp a raw command to the limits.

    Returns ``(command, speed_free, rate_free)``; the two flags are False where a clamp bit, and
    the caller must then hold the matching integrator (conditional-integration anti-windup).
    """
    if lim.max_speed == math.inf and lim.max_yaw_rate == math.inf and not lim.min_turn_radius:
        return Command(speed, yaw_rate, ux, uy), True, True     # nothing to clamp or hold
    speed_free = abs(speed) <= lim.max_speed
    speed = m.clip(speed, -lim.max_speed, lim.max_speed)
    top_rate = yaw_rate_limit(m, lim, speed)
    rate_free = abs(yaw_rate) <= top_rate
    yaw_rate = m.clip(yaw_rate, -top_rate, top_rate)
    # u_p for a velocity-vector autopilot (PX4) obeys the same speed limit.
    scale = m.minimum(1.0, lim.max_speed / m.maximum(norm_up, 1e-12))
    return Command(speed, yaw_rate, ux * scale, uy * scale), speed_free, rate_free


def keep_if(m: Ops, free: Num, new: Num, old: Num) -> Num:
    """Conditional integration: the new integrator value where ``free``, else the old one."""
    return new if free is True else m.where(free, new, old)
