"""What a steering-kind profile says: how a rover steers, as the autopilot's setup and the vehicle model show it.

One :class:`SteeringProfile` per kind (``skid.py``, ``ackermann.py``), registered in
``companion/profiles/__init__.py``: the output functions that make it on ArduPilot
(SERVOn_FUNCTION), its PX4 airframe (CA_AIRFRAME), whether it turns in place, the preflight
verdict on it (the paper's model is a differential drive: ``ok`` for that kind, ``warn`` with a
why for the others), the vehicle model's fields that describe it
(:class:`companion.sim.plant.RoverParams`) and the priors identification starts them from.
Its identification manoeuvre is named by ``manoeuvre``
(:func:`companion.ident.excite.manoeuvres`: a car's is flown at speed), and the robust
tuner's settings for it by ``tune_on_turn_rate``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

OK, WARN = "ok", "warn"        # companion.preflight.checks' statuses


@dataclass(frozen=True)
class SteeringProfile:
    name: str                          # "skid": flags, files
    label: str                         # "skid-steer": for people
    servo_functions: tuple[int, ...]   # ArduPilot SERVOn_FUNCTION values, all assigned
    servo_text: str                    # what they are, for people
    airframe: int                      # PX4 CA_AIRFRAME
    airframe_label: str                # PX4's name of that airframe
    turns_in_place: bool
    # identification's excitation manoeuvre for this kind (a name of companion.ident.excite.
    # manoeuvres: "turns in place", "turns at speed"), unless the autopilot flies its own
    manoeuvre: str
    verdict: str                       # preflight: OK (the vehicle model's kind) or WARN
    why: str                           # the preflight row's reason
    model_fields: tuple[str, ...]      # RoverParams fields describing it (0: not this kind)
    # identification's priors for this kind over the autopilot's (RoverParams field -> value)
    priors: tuple[tuple[str, float], ...] = ()
    priors_why: str = ""               # where they come from, for the vehicle file
    # The robust tuner's settings for this kind where the companion sends it speed and turn
    # rate (ArduPilot's); on velocity vectors the autopilot's own course loop steers it and
    # its profile's ``tune`` says all (companion.profiles.tune_settings).
    tune_on_turn_rate: tuple[tuple[str, Any], ...] = ()

    def prior_changes(self) -> Mapping[str, float]:
        return dict(self.priors)
