"""A vehicle, loaded once: what its file says, which autopilot and steering kind fly it, what it
can do (its limits), the gains tuned for it and the tuner's settings for it.

A command reads the vehicle file where it starts (:func:`companion.app.vehicle.load`: the one
place that opens one) and passes this record down; nothing below reads the file again. It is
pure: :func:`from_bytes` builds it from the file's bytes and the gains files found beside it.

May import: ``core``, ``sim``, ``profiles``, ``errors``.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import Any

from . import profiles
from .core.limits import DEFAULT_LIMITS, Limits
from .errors import UserError
from .profiles.autopilot import AutopilotProfile
from .profiles.steering import SteeringProfile
from .sim import vehicle_file
from .sim.gains import TunedGains
from .sim.plant import RoverParams


@dataclass(frozen=True)
class Vehicle:
    """One vehicle file, parsed once, with what follows from it."""

    file: vehicle_file.VehicleFile     # what the file says
    path: str                          # where it was read ("" : a built-in model)
    sha256: str                        # of its bytes: the gains tuned for it name it
    text: str                          # its text (the flight record keeps it)
    autopilot: AutopilotProfile
    steering: SteeringProfile
    kinds_named: bool = True           # False: the file did not name them (inferred)
    gains_beside: tuple[TunedGains, ...] = ()   # gains files beside it tuned for these bytes

    @property
    def params(self) -> RoverParams:
        return self.file.params

    @property
    def limits(self) -> Limits:
        return vehicle_limits(self.params)

    @property
    def tune_settings(self) -> dict[str, Any]:
        """The robust tuner's settings its autopilot and steering kind add, and the pose
        estimate's noise its file records (``[estimate]``, calibrate measures it) where that is
        more than the tuner's EKF-like default: the gains every shipped figure was tuned with
        stand for the quiet estimates, a noisier one is tuned for as measured."""
        from .sim.robust.config import RobustConfig  # (the tuner's: loaded to tune anyway)
        settings = profiles.tune_settings(self.autopilot, self.steering)
        measured = {"noise_pos": self.file.estimate.get("position_noise_m", 0.0),
                    "noise_yaw": self.file.estimate.get("yaw_noise_rad", 0.0)}
        for name, value in measured.items():
            if value > settings.get(name, getattr(RobustConfig, name)):
                settings[name] = value
        return settings

    def gains_at(self, rate: float) -> TunedGains | None:
        """The gains tuned for these very bytes at this loop rate, if any were found beside."""
        return next((g for g in self.gains_beside
                     if math.isclose(g.rate_hz, rate, rel_tol=1e-9)), None)

    def with_gains(self, gains: TunedGains) -> Vehicle:
        """The same vehicle with ``gains`` (tuned for it just now) among those beside it."""
        from dataclasses import replace
        return replace(self, gains_beside=(*self.gains_beside, gains))


def digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def from_bytes(data: bytes, path: str, gains_beside: tuple[TunedGains, ...] = ()) -> Vehicle:
    """The vehicle of a vehicle file's bytes ``data`` read from ``path``; ``gains_beside``:
    gains files found in its folder (those not tuned for these bytes are dropped). A profile
    name the registry does not know is a one-line UserError naming the file and key."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UserError(f"{path}: cannot read: {exc}") from None
    parsed = vehicle_file.loads(text, path)
    sha = digest(data)
    autopilot, steering = profiles.kinds_of_model(parsed.params)
    named = bool(parsed.autopilot and parsed.steering)
    if parsed.autopilot:
        autopilot = _named(profiles.AUTOPILOTS, parsed.autopilot, path, "autopilot")
    if parsed.steering:
        steering = _named(profiles.STEERING, parsed.steering, path, "steering")
    return Vehicle(file=parsed, path=path, sha256=sha, text=text, autopilot=autopilot,
                   steering=steering, kinds_named=named,
                   gains_beside=tuple(g for g in gains_beside if g.vehicle_sha256 == sha))


def _named(registry: dict[str, Any], name: str, path: str, key: str) -> Any:
    if name not in registry:
        raise UserError(f"{path}: {key}: {name!r} is not one of {', '.join(registry)}")
    return registry[name]


def vehicle_limits(vehicle: RoverParams, max_speed: float | None = None,
                   max_yaw_rate: float | None = None) -> Limits:
    """The companion's setpoint limits for a vehicle: what it can do (or the flags, if lower)."""
    def pick(flag: float | None, own: float, ceiling: float) -> float:
        own = own if math.isfinite(own) else ceiling    # none known: the companion's ceiling
        return min(flag, own) if flag is not None else own
    # a car driven by turn-rate setpoints: no command tighter than its turning radius (PX4's
    # velocity vectors leave that to PX4's own course loop)
    radius = float(vehicle.min_turn_radius) if vehicle.steered_by_radius else 0.0
    return Limits(max_speed=pick(max_speed, float(vehicle.max_speed), DEFAULT_LIMITS.max_speed),
                  max_yaw_rate=pick(max_yaw_rate, float(vehicle.max_yaw_rate),
                                    DEFAULT_LIMITS.max_yaw_rate),
                  min_turn_radius=radius)
