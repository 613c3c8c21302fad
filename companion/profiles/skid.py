"""Skid steering (a differential drive): the paper's own rover.

The wheels of each side are driven together, throttle left and right (ArduPilot SERVOn_FUNCTION
73 / 74; PX4 CA_AIRFRAME 6, "Rover (Differential)"); it turns in place, and the mixer shares the
motors' range between speed and turn rate (the model's two couplings,
:mod:`companion.sim.plant`).
"""

from __future__ import annotations

from .steering import OK, SteeringProfile

PROFILE = SteeringProfile(
    name="skid", label="skid-steer",
    servo_functions=(73, 74), servo_text="throttle left 73 / right 74",
    airframe=6, airframe_label="Rover (Differential)",
    turns_in_place=True,
    verdict=OK, why="a differential-drive rover: the vehicle model's kind",
    model_fields=("turn_speed_coupling", "speed_turn_coupling"))
