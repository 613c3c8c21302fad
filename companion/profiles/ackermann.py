"""Ackermann steering: steered front wheels and a throttle, a car.

ArduPilot SERVOn_FUNCTION 26 (ground steering) with 70 (throttle); PX4 CA_AIRFRAME 5, "Rover
(Ackermann)". It cannot turn in place and its turn rate follows its speed, at most |v| / R for
the turning radius R (the model's ``min_turn_radius``, :mod:`companion.sim.plant`). The paper's
model is a differential drive, so preflight warns.
"""

from __future__ import annotations

from .steering import WARN, SteeringProfile

PROFILE = SteeringProfile(
    name="ackermann", label="Ackermann",
    servo_functions=(26, 70), servo_text="ground steering 26, throttle 70",
    airframe=5, airframe_label="Rover (Ackermann)",
    turns_in_place=False,
    verdict=WARN,
    why=("an Ackermann rover cannot turn in place and its turn rate follows its speed; the "
         "paper's model is a differential drive: identify the vehicle (companion identify) and "
         "keep paths within its turning circle"),
    model_fields=("min_turn_radius",),
    # No parameter states the turning radius (steering geometry): 1 m, a small car's (ArduPilot
    # SITL's `rover` turns at 0.9 m), fitted from the manoeuvre's slow tight turns; a car's
    # mixer shares nothing between speed and steering, so no coupling.
    priors=(("min_turn_radius", 1.0), ("turn_speed_coupling", 0.0),
            ("speed_turn_coupling", 0.0)),
    priors_why="Ackermann steering")
