"""Which bundled vehicle a live vehicle is: ``run``'s safe default without a vehicle file.

A bundled vehicle file (``companion/sim/vehicles/``, e.g. ``ardupilot-skid``) was identified on
one vehicle; its ``[source]`` records the autopilot parameters read then (``ATC_ACCEL_MAX``,
``WP_SPEED``, ... : the profile's identification parameters). The autopilot's profile names
its presets and the steering kind each was identified on
(:attr:`~companion.profiles.autopilot.AutopilotProfile.presets`). A vehicle matches a preset
when it has that steering kind (its frame's parameters,
:func:`companion.profiles.steering_from_params`) and every recorded parameter it reports equals
the recorded value (within :data:`REL_TOL`; a parameter the vehicle does not report does not
match). Then ``run`` flies the preset's gains (the gains file shipped beside it, tuned for its
bytes at the rate flown) and its limits, and says so; otherwise it warns that the gains are not
for this vehicle and names the ``companion calibrate`` command (docs/flying.md).

:func:`match` is pure; :func:`recognise` reads the parameters (PARAM_REQUEST_READ): set-up
only, before the control loop. The bundled vehicles come in loaded
(:func:`companion.app.vehicle.bundled_for`): nothing here opens a file.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from .. import profiles
from ..profiles.autopilot import AutopilotProfile
from ..vehicle import Vehicle
from .policy import KnownVehicle

REL_TOL = 1e-3          # parameters travel as float32: 1 and 1.0000001 are the same setting


@dataclass(frozen=True)
class Recognised:
    """What ``run`` learnt of a vehicle flown without a vehicle file."""

    preset: str | None                 # the matching bundled vehicle, None: none
    vehicle: KnownVehicle              # its gains and limits (empty: none)
    note: str                          # the line ``run`` logs (a warning when none matched)


def recorded(profile: AutopilotProfile, preset: Vehicle) -> dict[str, float]:
    """The autopilot parameters the preset was identified with (its ``[source]``)."""
    return {k: float(v) for k, v in preset.file.source.items()
            if k in profile.ident.params and isinstance(v, (int, float))}


def match(profile: AutopilotProfile, values: Mapping[str, float],
          presets: Mapping[str, Mapping[str, float]]) -> tuple[str | None, str]:
    """(the first preset of ``presets`` (name -> recorded parameters) whose steering kind and
    parameters ``values`` has, why not (for the closest, the first parameter that differs))."""
    steering = profiles.steering_from_params(profile, dict(values))
    why = "no bundled vehicle for this autopilot"
    for name, params in presets.items():
        kind = profile.presets.get(name)
        if steering is None or steering.name != kind:
            why = (f"{name} is a {kind} rover; this one's frame shows "
                   f"{steering.label if steering is not None else 'no known steering kind'}")
            continue
        if not params:
            why = f"{name} records no parameters to match"
            continue
        differs = [(k, v) for k, v in params.items()
                   if k not in values or not math.isclose(values[k], v, rel_tol=REL_TOL,
                                                          abs_tol=1e-6)]
        if not differs:
            return name, ""
        k, v = differs[0]
        why = (f"{name} was identified with {k} {v:g}, this vehicle "
               + (f"has {values[k]:g}" if k in values else "does not report it"))
    return None, why


def recognise(link: Any, rate: float, calibrate_hint: str,
              read: Callable[[Any, list[str]], dict[str, float]],
              bundled: Mapping[str, Vehicle]) -> Recognised:
    """Match the vehicle on ``link`` against its autopilot's presets (``bundled``: the bundled
    vehicles by name, loaded); ``read(link, names)`` reads parameters
    (:func:`companion.live.params.read_values`); ``calibrate_hint`` the command to name when
    none matches. The preset's gains must be tuned for ``rate``."""
    profile = link.vehicle.profile
    mine = {name: bundled[name] for name in profile.presets if name in bundled}
    presets = {name: recorded(profile, v) for name, v in mine.items()}
    names = sorted({*profile.ident.params, *profiles.steering_params(profile)})
    values = read(link, names) if presets else {}
    name, why = match(profile, values, presets)
    warning = (f"WARNING: the gains are not tuned for this vehicle ({why}); calibrate it: "
               f"{calibrate_hint}, then companion run --vehicle DIR/vehicle.toml")
    if name is None:
        return Recognised(None, KnownVehicle(), warning)
    preset = mine[name]
    gains = preset.gains_at(rate)
    if gains is None:
        return Recognised(None, KnownVehicle(), warning.replace(
            f"({why})", f"(it is the bundled {name}, whose gains are tuned for other rates "
                        f"than {rate:g} Hz)"))
    params = preset.params
    known = KnownVehicle(gains=gains, limits=preset.limits, w_c=float(params.w_c),
                         d_cen=float(params.d_cen))
    shown = ", ".join(f"{k} {v:g}" for k, v in presets[name].items())
    return Recognised(name, known, f"the vehicle matches the bundled {name} ({shown}): flying "
                                   f"its gains and limits (--vehicle {preset.path})")
