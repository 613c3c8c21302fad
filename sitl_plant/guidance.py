"""The autopilot's own inner guidance: a guidance target -> (speed, turn-rate) commands.

Stands in for ArduPilot's steering/speed controllers (and PX4's rover heading loop): proportional
on heading error, clamped turn rate, and a pivot turn (no forward speed) while the heading error
exceeds ``pivot_angle`` (ArduPilot's WP_PIVOT_ANGLE, 60 deg on skid-steer rovers). Position
targets are chased with simple pursuit at a speed that shrinks near the point and stop within
``arrive_radius``. Deliberately simple: the companion under test is the real controller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.core.angles import wrap
from companion.profiles.setpoint import HeadingSpeed, PositionTarget, Target, TurnRateSpeed
from companion.sim.plant import RoverParams, RoverState


@dataclass(frozen=True)
class GuidanceConfig:
    heading_gain: float = 2.0                   # turn rate per rad of heading error, 1/s
    pivot_angle: float = math.radians(60.0)     # WP_PIVOT_ANGLE
    cruise_speed: float = 2.0                   # WP_SPEED default, m/s, for position targets
    approach_gain: float = 0.5                  # position targets: speed = gain * distance, 1/s
    arrive_radius: float = 0.5                  # position targets: stop within this, m
    turn_rate_cap: float = math.radians(90.0)   # used when the vehicle itself has no limit


def _turn_rate_limit(params: RoverParams, cfg: GuidanceConfig) -> float:
    limit = params.max_yaw_rate
    return limit if math.isfinite(limit) else cfg.turn_rate_cap


def _steer(heading: float, speed: float, s: RoverState, params: RoverParams,
           cfg: GuidanceConfig) -> tuple[float, float]:
    error = wrap(heading - s.yaw)
    limit = _turn_rate_limit(params, cfg)
    rate = max(-limit, min(limit, cfg.heading_gain * error))
    if abs(error) > cfg.pivot_angle:
        speed = 0.0
    return speed, rate


def commands(target: Target | None, s: RoverState, params: RoverParams,
             cfg: GuidanceConfig) -> tuple[float, float]:
    """(speed, yaw_rate) commands for the vehicle's actuators; (0, 0) without a target."""
    if target is None:
        return 0.0, 0.0
    if isinstance(target, TurnRateSpeed):
        return target.speed, target.yaw_rate
    if isinstance(target, HeadingSpeed):
        return _steer(target.heading, target.speed, s, params, cfg)
    if isinstance(target, PositionTarget):
        dx, dy = target.x - s.x, target.y - s.y
        distance = math.hypot(dx, dy)
        if distance < cfg.arrive_radius:
            return 0.0, 0.0
        speed = min(cfg.cruise_speed, params.max_speed, cfg.approach_gain * distance)
        return _steer(math.atan2(dy, dx), speed, s, params, cfg)
    raise TypeError(f"unknown target {target!r}")
