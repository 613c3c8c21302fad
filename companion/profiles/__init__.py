"""Profiles: what differs between autopilots (ardupilot, px4) and between steering kinds (skid, ackermann), one module each behind one small interface.

May import: ``core``, ``sim`` (rover parameters, for priors), ``errors``; no I/O, no pymavlink.
"""

from __future__ import annotations

from typing import Any

from . import ackermann, ardupilot, px4, skid, steering
from .autopilot import AutopilotProfile
from .steering import SteeringProfile

# Adding one: a module beside these with its PROFILE, and one line here (docs/design/profiles.md).
AUTOPILOTS: dict[str, AutopilotProfile] = {p.name: p for p in (
    ardupilot.PROFILE,
    px4.PROFILE,
)}
STEERING: dict[str, SteeringProfile] = {p.name: p for p in (
    skid.PROFILE,
    ackermann.PROFILE,
)}
DEFAULT_AUTOPILOT = next(iter(AUTOPILOTS))     # the plant's and the demo's default


def autopilot_named(name: str) -> AutopilotProfile:
    """The profile called ``name`` (KeyError for another: the registry's names are the
    flags' choices). Not ``autopilot``: that is the interface's module."""
    return AUTOPILOTS[name]


def from_heartbeat(mav_autopilot: int) -> AutopilotProfile | None:
    """The profile of a HEARTBEAT's ``autopilot`` field; None for an autopilot not driven here."""
    return next((p for p in AUTOPILOTS.values() if mav_autopilot in p.mav_autopilot), None)


def default_autopilot() -> AutopilotProfile:
    """The profile of a vehicle that says nothing else (the plant's and the demo's default; a
    log without a heartbeat)."""
    return AUTOPILOTS[DEFAULT_AUTOPILOT]


def autopilot_of_model(params) -> AutopilotProfile:
    """The autopilot a vehicle model was identified on (``params``: a RoverParams): the first
    whose own fields (``model_fields``: PX4's course loop) are set in it, else the default.
    For a vehicle known only by its model (a vehicle file); one that names its autopilot
    passes the profile instead."""
    return next((p for p in AUTOPILOTS.values()
                 if any(float(getattr(params, f)) > 0 for f in p.model_fields)),
                default_autopilot())


def prior_params() -> tuple[str, ...]:
    """Every profile's identification parameters (a .tlog may hold any of them)."""
    return tuple(dict.fromkeys(n for p in AUTOPILOTS.values() for n in p.ident.params))


def model_steering() -> SteeringProfile:
    """The steering kind the vehicle model is (preflight's ``ok``): the paper's differential
    drive."""
    return next(s for s in STEERING.values() if s.verdict == steering.OK)


def steering_of_model(params) -> SteeringProfile:
    """The steering kind a vehicle model is (``params``: a RoverParams): the first kind other
    than the model's own whose fields (``model_fields``) are set in it, else the model's
    (a turning radius: a car; what a plant emulating it serves)."""
    return next((s for s in STEERING.values() if s.verdict != steering.OK
                 and any(float(getattr(params, f)) > 0 for f in s.model_fields)),
                model_steering())


def steering_by_airframe(airframe: int) -> SteeringProfile | None:
    return next((s for s in STEERING.values() if s.airframe == airframe), None)


def steering_by_servos(functions: set[int] | frozenset[int]) -> SteeringProfile | None:
    """The first steering kind whose output functions are all assigned."""
    return next((s for s in STEERING.values()
                 if all(f in functions for f in s.servo_functions)), None)


def steering_params(profile: AutopilotProfile) -> tuple[str, ...]:
    """The parameters that tell this autopilot's steering kind (its frame's)."""
    return profile.preflight.frame.params()


def steering_from_params(profile: AutopilotProfile,
                         values: dict[str, float]) -> SteeringProfile | None:
    """The steering kind the parameters ``values`` (``{name: value}``) show, None if none."""
    return profile.preflight.frame.steering(values)


__all__ = ["AUTOPILOTS", "STEERING", "DEFAULT_AUTOPILOT", "AutopilotProfile", "SteeringProfile",
           "autopilot_named", "from_heartbeat", "default_autopilot", "autopilot_of_model",
           "kinds_of_model", "prior_params", "model_steering", "steering_of_model", "steering_by_airframe", "steering_by_servos", "steering_params",
           "steering_from_params"]


def kinds_of_model(params) -> tuple[AutopilotProfile, SteeringProfile]:
    """(the autopilot, the steering kind) a vehicle model is flown by, for a vehicle file that
    does not name them: the autopilot whose fields it sets (:func:`autopilot_of_model`), the
    steering kind whose fields it sets (:func:`steering_of_model`)."""
    return autopilot_of_model(params), steering_of_model(params)


def tune_settings(autopilot: AutopilotProfile, steering_kind: SteeringProfile) -> dict[str, Any]:
    """The robust tuner's settings for a vehicle flown by ``autopilot`` with ``steering_kind``:
    the autopilot's (``tune``), then, on speed / turn-rate setpoints, the steering kind's
    (``tune_on_turn_rate``; the steering kind's win where both say). Names are RobustConfig's
    (companion.sim.vehicle_gains.config_for)."""
    settings = dict(autopilot.tune)
    if not autopilot.setpoint.velocity_vector:     # velocity vectors: its course loop steers
        settings.update(steering_kind.tune_on_turn_rate)
    return settings
