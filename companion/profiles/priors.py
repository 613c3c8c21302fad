"""What identification assumes before it sees a log: the prior type and the baseline every profile starts from.

A log rarely excites everything (a top speed never reached, a turn never sharp enough to hit the
rate limit), and a parameter it does not determine takes its prior. Each autopilot profile makes
priors from its own limit parameters (``IdentFacts.priors``: read live with PARAM_REQUEST_READ,
or found as PARAM_VALUE in a .tlog); what no parameter gives comes from :func:`defaults`, a stock
ArduPilot Rover's values (``vehicle-interfaces.md``: ATC_ACCEL_MAX 1 m/s^2, ATC_STR_ACC_MAX
120 deg/s^2, ATC_STR_RAT_MAX 120 deg/s, about 4 m/s top speed) and, for what no parameter
states (delays, lags, the couplings), deliberately sluggish values: a model that assumes a slower
vehicle than the real one makes a tuner cautious, not unstable.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..sim.plant import RoverParams
    from .steering import SteeringProfile


@functools.cache
def defaults() -> RoverParams:
    """The baseline priors. Made on first use: the registry is read when the command line is
    built (flag choices), and the rover model's module brings numpy."""
    from ..sim.plant import RoverParams
    return RoverParams(
        w_c=1.0 / 0.4, w_c_yaw=1.0 / 0.15,           # lags: 0.4 s speed, 0.15 s turn rate
        speed_delay=0.1, yaw_delay=0.1,                # s
        max_speed=4.0, max_yaw_rate=math.radians(120.0),
        max_accel=1.0, max_decel=None,                 # None: as the identified acceleration
        max_yaw_accel=math.radians(120.0), max_yaw_decel=None,
        turn_speed_coupling=0.5,                       # skid-steer mixing, MOT_STR_THR_MIX's default
        # and the turn rate it gives up at full speed: 2.1 rad/s in place, about 1.8 at full
        # throttle on ArduPilot SITL rover-skid (the cautious side of none)
        speed_turn_coupling=0.15,
        speed_overshoot=0.0, speed_overshoot_s=1.0,       # none: what most speed loops do
        yaw_overshoot=0.0, yaw_overshoot_s=1.0)           # one time scale: a matched feed-forward


@dataclass(frozen=True)
class Priors:
    params: RoverParams
    source: dict[str, str] = field(default_factory=dict)   # RoverParams field -> where from
    steering: SteeringProfile | None = None    # the kind the parameters show (None: not known)

    def with_steering(self, kind: SteeringProfile | None) -> Priors:
        """These priors with the steering kind's own (:attr:`SteeringProfile.priors`) over
        them: what no autopilot parameter states about how the rover steers."""
        if kind is None:
            return self
        changes = kind.prior_changes()
        source = {**self.source, **{name: kind.priors_why for name in changes}}
        return Priors(self.params.with_(**changes), source, kind)

    def describe(self, name: str) -> str:
        return self.source.get(name, "default")


def finite(values: Mapping[str, float], key: str) -> float | None:
    """``values[key]`` as a float, None when missing or not finite."""
    value = values.get(key)
    if value is None or not math.isfinite(value):
        return None
    return float(value)
