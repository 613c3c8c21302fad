"""What identification assumes before it sees a log: priors for every model parameter.

A log rarely excites everything (a top speed never reached, a turn never sharp enough to hit the
rate limit), and a parameter it does not determine takes its prior. The priors come from the
autopilot's own limit parameters when they are known (read live with PARAM_REQUEST_READ, or
found as PARAM_VALUE in a .tlog), otherwise from :data:`DEFAULTS`, a stock ArduPilot Rover's
values (``vehicle-interfaces.md``: ATC_ACCEL_MAX 1 m/s^2, ATC_STR_ACC_MAX 120 deg/s^2,
ATC_STR_RAT_MAX 120 deg/s, about 4 m/s top speed) and, for what no parameter states (delays,
lags, the couplings), deliberately sluggish values: a model that assumes a slower vehicle than the
real one makes a tuner cautious, not unstable.

How ArduPilot Rover's parameters map onto :class:`companion.sim.plant.RoverParams`
(APM_Control/AR_AttitudeControl.cpp):

* ``ATC_ACCEL_MAX`` (m/s^2, 0 = no limit) -> ``max_accel``; ``ATC_DECEL_MAX`` (0 = as accel)
  -> ``max_decel`` (None: the identified acceleration limit);
* ``ATC_STR_ACC_MAX`` (deg/s^2, 0 = no limit) -> ``max_yaw_accel``; ``ATC_STR_DEC_MAX`` where
  the firmware has it (0 = as accel) -> ``max_yaw_decel``;
* ``ATC_STR_RAT_MAX`` (deg/s, 0 = no limit) -> ``max_yaw_rate``;
* ``WP_SPEED`` (m/s) -> ``max_speed``: GUIDED holds a faster speed setpoint to it (as seen on
  SITL: docs/design/vehicle-model.md); no faster than full throttle,
  CRUISE_SPEED * 100 / CRUISE_THROTTLE (ArduPilot's throttle feed-forward assumes speed
  proportional to throttle), which is the prior without WP_SPEED.

``MOT_STR_THR_MIX`` is read and recorded but sets nothing: how steering and throttle share the
motors is not the model's coupling share, which only a turn at speed shows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..sim.plant import RoverParams

# The autopilot parameters a live identification reads (PARAM_REQUEST_READ).
AUTOPILOT_PARAMS = ("ATC_ACCEL_MAX", "ATC_DECEL_MAX", "ATC_STR_ACC_MAX", "ATC_STR_DEC_MAX",
                    "ATC_STR_RAT_MAX", "CRUISE_SPEED", "CRUISE_THROTTLE", "WP_SPEED",
                    "MOT_STR_THR_MIX")

# The fields identification fits, turn-rate channel first (the speed channel's coupling needs
# the turn rate; the turn-rate channel's coupling is driven by the measured speed), with the
# vehicle file's names for people.
YAW_FIELDS = ("yaw_delay", "w_c_yaw", "max_yaw_rate", "max_yaw_accel", "max_yaw_decel",
              "speed_turn_coupling")
SPEED_FIELDS = ("speed_delay", "w_c", "max_speed", "max_accel", "max_decel", "turn_speed_coupling")
FILE_NAMES = {"speed_delay": "speed.delay_s", "w_c": "speed.lag_s", "max_speed": "speed.max_m_s",
              "max_accel": "speed.accel_max_m_s2", "max_decel": "speed.decel_max_m_s2",
              "yaw_delay": "turn_rate.delay_s", "w_c_yaw": "turn_rate.lag_s",
              "max_yaw_rate": "turn_rate.max_rad_s", "max_yaw_accel": "turn_rate.accel_max_rad_s2",
              "max_yaw_decel": "turn_rate.decel_max_rad_s2",
              "turn_speed_coupling": "coupling.turn_speed",
              "speed_turn_coupling": "coupling.speed_turn",
              "course_gain": "course.gain_1_s", "min_turn_radius": "course.min_turn_radius_m"}
COURSE_FIELDS = ("course_gain", "min_turn_radius")     # PX4's velocity-vector interface

DEFAULTS = RoverParams(
    w_c=1.0 / 0.4, w_c_yaw=1.0 / 0.15,           # lags: 0.4 s speed, 0.15 s turn rate
    speed_delay=0.1, yaw_delay=0.1,                # s
    max_speed=4.0, max_yaw_rate=math.radians(120.0),
    max_accel=1.0, max_decel=None,                 # None: as the identified acceleration
    max_yaw_accel=math.radians(120.0), max_yaw_decel=None,
    turn_speed_coupling=0.5,                       # skid-steer mixing, MOT_STR_THR_MIX's default
    # and the turn rate it gives up at full speed: 2.1 rad/s in place, about 1.8 at full
    # throttle on ArduPilot SITL rover-skid (the cautious side of none)
    speed_turn_coupling=0.15)


@dataclass(frozen=True)
class Priors:
    params: RoverParams
    source: dict[str, str] = field(default_factory=dict)   # RoverParams field -> where from

    def describe(self, name: str) -> str:
        return self.source.get(name, "default")


def _positive(values: dict[str, float], key: str) -> float | None:
    value = values.get(key)
    if value is None or not math.isfinite(value):
        return None
    return float(value)


def from_autopilot(values: dict[str, float]) -> Priors:
    """Priors from the autopilot's parameters (``{name: value}``, any subset; others default)."""
    changes: dict[str, float | None] = {}
    source: dict[str, str] = {}

    def take(name: str, value: float | None, why: str) -> None:
        changes[name] = value
        source[name] = why

    accel = _positive(values, "ATC_ACCEL_MAX")
    if accel is not None:
        take("max_accel", accel if accel > 0 else math.inf, f"ATC_ACCEL_MAX {accel:g}")
    decel = _positive(values, "ATC_DECEL_MAX")
    if decel is not None:
        take("max_decel", decel if decel > 0 else None, f"ATC_DECEL_MAX {decel:g}")
    yaw_accel = _positive(values, "ATC_STR_ACC_MAX")
    if yaw_accel is not None:
        take("max_yaw_accel", math.radians(yaw_accel) if yaw_accel > 0 else math.inf,
             f"ATC_STR_ACC_MAX {yaw_accel:g} deg/s^2")
    yaw_decel = _positive(values, "ATC_STR_DEC_MAX")
    if yaw_decel is not None:
        take("max_yaw_decel", math.radians(yaw_decel) if yaw_decel > 0 else None,
             f"ATC_STR_DEC_MAX {yaw_decel:g} deg/s^2")
    rate = _positive(values, "ATC_STR_RAT_MAX")
    if rate is not None:
        take("max_yaw_rate", math.radians(rate) if rate > 0 else math.inf,
             f"ATC_STR_RAT_MAX {rate:g} deg/s")
    cruise, throttle = _positive(values, "CRUISE_SPEED"), _positive(values, "CRUISE_THROTTLE")
    full = (cruise * 100.0 / throttle) if cruise and throttle and cruise > 0 and throttle > 0 \
        else None
    wp_speed = _positive(values, "WP_SPEED")
    if wp_speed is not None and wp_speed > 0 and (full is None or wp_speed <= full):
        take("max_speed", wp_speed, f"WP_SPEED {wp_speed:g}")
    elif full is not None:
        take("max_speed", full, f"CRUISE_SPEED {cruise:g} / CRUISE_THROTTLE {throttle:g} %")
    return Priors(DEFAULTS.with_(**changes), source)


# --------------------------------------------------------------------------- PX4

# PX4 rover parameters a live identification reads on a PX4 vehicle (rover_ackermann /
# rover_differential, PX4 main 2025-2026; RO_* are shared by every rover, RA_* are Ackermann's).
PX4_PARAMS = ("RO_SPEED_LIM", "RO_ACCEL_LIM", "RO_DECEL_LIM", "RO_YAW_P", "RO_YAW_RATE_LIM",
              "RO_YAW_ACCEL_LIM", "RO_YAW_DECEL_LIM", "RA_WHEEL_BASE", "RA_MAX_STR_ANG")

# PX4's velocity-vector interface (RoverParams.course_gain > 0) before any parameter is known:
# a slow course loop and a wide turning circle (the cautious side), no skid-steer coupling.
PX4_DEFAULTS = DEFAULTS.with_(course_gain=2.0, min_turn_radius=1.0, turn_speed_coupling=0.0,
                              speed_turn_coupling=0.0, max_accel=1.0)


def from_px4(values: dict[str, float]) -> Priors:
    """Priors for a PX4 rover from its parameters (any subset; others default):

    * ``RO_SPEED_LIM`` -> ``max_speed``; ``RO_ACCEL_LIM`` / ``RO_DECEL_LIM`` (m/s^2, 0 = none)
      -> ``max_accel`` / ``max_decel``;
    * ``RO_YAW_P`` (the course loop: yaw rate per rad of heading error) -> ``course_gain``;
      ``RO_YAW_RATE_LIM``, ``RO_YAW_ACCEL_LIM``, ``RO_YAW_DECEL_LIM`` (deg/s, deg/s^2)
      -> the turn-rate clamp and limits;
    * ``RA_WHEEL_BASE`` / tan(``RA_MAX_STR_ANG``) (m, rad) -> ``min_turn_radius`` (Ackermann).
    """
    changes: dict[str, float | None] = {}
    source: dict[str, str] = {}

    def take(name: str, value: float | None, why: str) -> None:
        changes[name] = value
        source[name] = why

    for key, name in (("RO_SPEED_LIM", "max_speed"), ("RO_ACCEL_LIM", "max_accel"),
                      ("RO_DECEL_LIM", "max_decel")):
        value = _positive(values, key)
        if value is not None:
            take(name, value if value > 0 else math.inf, f"{key} {value:g}")
    gain = _positive(values, "RO_YAW_P")
    if gain is not None and gain > 0:
        take("course_gain", gain, f"RO_YAW_P {gain:g}")
    for key, name in (("RO_YAW_RATE_LIM", "max_yaw_rate"), ("RO_YAW_ACCEL_LIM", "max_yaw_accel"),
                      ("RO_YAW_DECEL_LIM", "max_yaw_decel")):
        value = _positive(values, key)
        if value is not None:
            take(name, math.radians(value) if value > 0 else math.inf, f"{key} {value:g} deg/s")
    base, angle = _positive(values, "RA_WHEEL_BASE"), _positive(values, "RA_MAX_STR_ANG")
    if base and angle and base > 0 and 0 < angle < math.pi / 2:
        take("min_turn_radius", base / math.tan(angle),
             f"RA_WHEEL_BASE {base:g} / tan(RA_MAX_STR_ANG {angle:g})")
    elif values and base is None:
        take("min_turn_radius", 0.0, "no RA_WHEEL_BASE: not an Ackermann rover")
    return Priors(PX4_DEFAULTS.with_(**changes), source)
