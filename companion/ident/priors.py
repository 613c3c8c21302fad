"""What identification fits and calls it: the fields of the vehicle model, channel by channel, and their names in a vehicle file.

The priors themselves (what a parameter a log does not determine is taken to be) are the
autopilot's: each profile makes them from its own parameters
(:attr:`companion.profiles.autopilot.IdentFacts.priors`; ArduPilot's ATC_* and cruise speeds,
PX4's RO_* / RA_*), over the baseline :func:`companion.profiles.priors.defaults`.
"""

from __future__ import annotations

from ..profiles.priors import Priors

__all__ = ["COURSE_FIELDS", "FILE_NAMES", "Priors", "SPEED_FIELDS", "YAW_FIELDS"]

# The fields identification fits, turn-rate channel first (the speed channel's coupling needs
# the turn rate; the turn-rate channel's coupling is driven by the measured speed), with the
# vehicle file's names for people.
# (each channel's overshoot last: the fit searches it after the others)
YAW_FIELDS = ("yaw_delay", "w_c_yaw", "max_yaw_rate", "max_yaw_accel", "max_yaw_decel",
              "speed_turn_coupling", "yaw_overshoot", "yaw_overshoot_s")
SPEED_FIELDS = ("speed_delay", "w_c", "max_speed", "max_accel", "max_decel", "turn_speed_coupling",
                "speed_overshoot", "speed_overshoot_s")
FILE_NAMES = {"speed_delay": "speed.delay_s", "w_c": "speed.lag_s", "max_speed": "speed.max_m_s",
              "max_accel": "speed.accel_max_m_s2", "max_decel": "speed.decel_max_m_s2",
              "yaw_delay": "turn_rate.delay_s", "w_c_yaw": "turn_rate.lag_s",
              "max_yaw_rate": "turn_rate.max_rad_s", "max_yaw_accel": "turn_rate.accel_max_rad_s2",
              "max_yaw_decel": "turn_rate.decel_max_rad_s2",
              "turn_speed_coupling": "coupling.turn_speed",
              "speed_turn_coupling": "coupling.speed_turn",
              "course_gain": "course.gain_1_s", "min_turn_radius": "course.min_turn_radius_m",
              "max_lat_accel": "turn_rate.lat_accel_max_m_s2",
              "speed_overshoot": "speed.overshoot", "speed_overshoot_s": "speed.overshoot_s",
              "yaw_overshoot": "turn_rate.overshoot", "yaw_overshoot_s": "turn_rate.overshoot_s"}
COURSE_FIELDS = ("course_gain", "min_turn_radius")     # PX4's velocity-vector interface
