"""The ensemble: the identified vehicle and its neighbours, and their parameters stacked into
one batch."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..plant import RoverParams
from .config import Spread


def ensemble(vehicle: RoverParams, count: int, spread: Spread, sample_period: float,
             seed: int) -> list[RoverParams]:
    """The identified vehicle first, then ``count`` neighbours: the slow corner (longer lags,
    lower limits, later) always among them, the rest drawn at random within ``spread``."""
    rng = np.random.default_rng(seed)
    # The turn-rate side of the mixing (speed_turn_coupling) is drawn from its own stream, so
    # every other draw stays what it was before it was modelled; and apart from the speed
    # side's, because a mixer that favours steering gives up speed and keeps turn rate.
    rng_turn = np.random.default_rng([seed, 1])
    rng_drive = np.random.default_rng([seed, 2])    # (the same way for the over-drive)
    out = [vehicle]
    for i in range(count):
        if i == 0:
            lag_k, lim_k, extra, dc = 1 + spread.lag, 1 - spread.limit, spread.delay_samples, 0.0
            dcw = 0.0
        elif i == 1:
            lag_k, lim_k, extra, dc = 1 - spread.lag / 2, 1 + spread.limit, 0.0, -spread.coupling
            dcw = -spread.coupling
        else:
            lag_k = 1 + spread.lag * rng.uniform(-0.5, 1.0)
            lim_k = 1 + spread.limit * rng.uniform(-1.0, 1.0)
            extra = float(rng.integers(-1, int(spread.delay_samples) + 1))
            dc = spread.coupling * rng.uniform(-1.0, 1.0)
            dcw = spread.coupling * rng_turn.uniform(-1.0, 1.0)
        delay = extra * sample_period
        # PX4's course loop and an Ackermann rover's turning radius vary as a lag and a limit do
        course_gain = vehicle.course_gain / lag_k
        turn_radius = vehicle.min_turn_radius / lim_k
        out.append(vehicle.with_(
            course_gain=course_gain, min_turn_radius=turn_radius,
            w_c=vehicle.w_c / lag_k, w_c_yaw=vehicle.yaw_bandwidth / lag_k,
            max_accel=vehicle.max_accel * lim_k, max_decel=vehicle.decel * lim_k,
            max_yaw_accel=vehicle.max_yaw_accel * lim_k, max_yaw_decel=vehicle.yaw_decel * lim_k,
            max_lat_accel=vehicle.max_lat_accel * lim_k,
            speed_delay=max(0.0, vehicle.speed_delay + delay),
            yaw_delay=max(0.0, vehicle.yaw_delay + delay),
            turn_speed_coupling=float(np.clip(vehicle.turn_speed_coupling + dc, 0.0, 1.0)),
            speed_turn_coupling=float(np.clip(vehicle.speed_turn_coupling + dcw, 0.0, 1.0))))
        if spread.over_drive > 0 and i != 1:
            # the slow corner over-drives fully, the random ones by a share of it
            share = 1.0 if i == 0 else float(rng_drive.uniform(0.0, 1.0))
            out[-1] = out[-1].with_(speed_overshoot=spread.over_drive * share,
                                    speed_overshoot_s=math.inf)
    return out


def stack_params(vehicles: Sequence[RoverParams], repeat: int, tile: int) -> RoverParams:
    """One RoverParams of arrays: each vehicle's values ``repeat`` times in a row, the whole
    sequence ``tile`` times (vehicle order: candidate, then vehicle, then reference)."""
    values = {k: [float(getattr(v, k)) for v in vehicles] for k in
              ("d_cen", "w_c", "max_speed", "max_yaw_rate", "max_accel", "max_yaw_accel",
               "speed_delay", "yaw_delay", "turn_speed_coupling", "speed_turn_coupling",
               "course_gain", "min_turn_radius", "max_lat_accel", "speed_overshoot",
               "speed_overshoot_s", "yaw_overshoot", "yaw_overshoot_s")}
    values["w_c_yaw"] = [float(v.yaw_bandwidth) for v in vehicles]
    values["max_decel"] = [float(v.decel) for v in vehicles]
    values["max_yaw_decel"] = [float(v.yaw_decel) for v in vehicles]
    return RoverParams(**{k: np.tile(np.repeat(v, repeat), tile) for k, v in values.items()})
