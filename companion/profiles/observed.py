"""What preflight observed of a vehicle, and the rows a check gives: the interface between the preflight frontend and each autopilot's checks.

``companion preflight`` (:mod:`companion.preflight.checks`, the frontend) gathers an
:class:`Observed` and runs its checks; the checks that differ between autopilots (how the frame
shows the steering kind, the failsafe for a companion that falls silent) are the autopilot
profile's own (``PreflightFacts.frame`` / ``failsafe``, each with a ``check(obs)``), and every
check returns :class:`Check` rows. A row may carry ``fix``, the parameter values ``companion
preflight --fix`` would set; only what has one right answer for every rover gets one (failsafe
settings), never a vehicle's own limits.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .steering import OK, WARN

if TYPE_CHECKING:
    from .autopilot import AutopilotProfile

FAIL = "fail"
__all__ = ["OK", "WARN", "FAIL", "Check", "Ekf", "Streams", "Limits", "Observed", "num",
           "missing"]


@dataclass(frozen=True)
class Check:
    name: str            # the parameter or message looked at
    status: str          # OK, WARN or FAIL
    value: str           # what the vehicle has
    want: str            # what to set
    why: str
    fix: Mapping[str, float] = field(default_factory=dict)   # --fix: parameter -> value

    def as_dict(self) -> dict[str, str]:
        return {"name": self.name, "status": self.status, "value": self.value,
                "want": self.want, "why": self.why}


@dataclass(frozen=True)
class Ekf:
    flags: int
    velocity_variance: float = 0.0
    pos_horiz_variance: float = 0.0
    pos_vert_variance: float = 0.0
    compass_variance: float = 0.0


@dataclass(frozen=True)
class Streams:
    """What SET_MESSAGE_INTERVAL for the pose messages did, and what then arrived."""
    asked_hz: float
    results: Mapping[str, int | None]          # message -> COMMAND_ACK result (None: no ACK)
    measured_hz: Mapping[str, float | None]    # message -> rate on the vehicle's clock


@dataclass(frozen=True)
class Limits:
    """The vehicle model's limits (a vehicle file), to hold against the autopilot's."""
    max_speed: float            # m/s
    max_accel: float            # m/s^2
    max_decel: float            # m/s^2
    max_yaw_rate: float         # rad/s
    max_yaw_accel: float        # rad/s^2
    source: str = "the vehicle file"


@dataclass(frozen=True)
class Observed:
    autopilot: str                          # a profile's name (companion.profiles.AUTOPILOTS)
    mav_type: int
    modes: frozenset[str]                   # the mode names the vehicle type has
    armed: bool = False
    mavlink_version: int = 2                # of the vehicle's frames
    signed: bool = False                    # the vehicle's frames carry a signature
    signing_key: bool = False               # the companion signs (and verified the vehicle's)
    serial: bool = False                    # the link is a serial device (a wire)
    companion_sysid: int = 255
    vehicle_sysid: int | None = None        # the vehicle's (the companion's too, by default)
    params: Mapping[str, float] = field(default_factory=dict)
    sensors: tuple[int, int, int] | None = None      # SYS_STATUS present, enabled, health
    prearm_texts: tuple[str, ...] = ()
    ekf: Ekf | None = None
    origin: tuple[float, float] | None = None        # GPS_GLOBAL_ORIGIN lat, lon (deg)
    streams: Streams | None = None
    limits: Limits | None = None

    @property
    def profile(self) -> AutopilotProfile:
        from . import autopilot_named  # the registry imports the profiles, which import this
        return autopilot_named(self.autopilot)


def num(value: float) -> str:
    return f"{value:g}"


def missing(name: str, obs: Observed, want: str, why: str) -> Check | None:
    """A 'could not read' row for a parameter the vehicle did not report, else None."""
    if name in obs.params and math.isfinite(obs.params[name]):
        return None
    return Check(name, WARN, "not reported", want,
                 f"the vehicle did not report {name} (another firmware version?): {why}")
