"""Which parameters the logs determine, and how tightly.

What the log does not determine: around the best, each parameter is moved by a clear step
(lags and limits x1.5 and /1.5, delays 50 ms, the couplings 0.15). If the RMS moves by less than
``tol`` (2 %) either way, or, for a clamp or a rate limit, when raising it changes nothing (the
limit never bound: the log gives only a lower bound), the parameter is *undetermined*: it moves
towards its prior (:mod:`companion.ident.priors`) as far as the log allows (the RMS within
``tol``): all the way (status ``prior``), or part of the way when the log contradicts the prior
(status ``bound``: e.g. a top speed the log shows is at least 4.3 m/s against a prior of 4 ends
at the lowest value the log allows, a cautious model).

Each fitted parameter then says over which range, and by which of the joined logs, it is
determined (:class:`Determined`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..sim.plant import RoverParams
from .objective import Objective
from .search import COUPLINGS, DELAYS, LIMITS, YAW_OVERSHOOT, Dim, Search

FITTED, PRIOR, BOUND = "fitted", "prior", "bound"


@dataclass(frozen=True)
class Determined:
    """How tightly the logs pin one fitted parameter: the range of values (``lo``, ``hi``, in
    RoverParams' units; -inf / inf: the scan's end reached, the log bounds it on one side only)
    over which every log's RMS stays within ``tol`` of its own with the other parameters held,
    and which logs (indices into the joined series' parts) move by more than ``tol`` within
    the scan: the logs that determine it."""

    lo: float
    hi: float
    logs: tuple[int, ...]


def settle(channel: Objective, dims: list[Dim], best: dict[str, float], prior: RoverParams,
           cfg: Search) -> tuple[dict[str, float], dict[str, str]]:
    """Which parameters the log determines; the others move to their prior as far as the log
    allows (all of the way: PRIOR; part of the way: BOUND). Returns (values, status).
    With several logs joined, each is held to its own RMS: a parameter one log shows is
    determined, and a move must keep every log within ``tol`` (on the joined RMS, a log that
    never drives the channel would dilute what another shows)."""
    names = [dim.name for dim in dims]
    by_name = {dim.name: dim for dim in dims}

    keys = list(best)                      # every parameter of the channel, moved or not

    def within(rows: list[dict[str, float]]) -> np.ndarray:
        """Per row: every log's RMS within its limit."""
        cost = channel.cost({k: np.array([row[k] for row in rows]) for k in keys}, len(rows),
                            cfg.check_dt, per_log=True)
        return np.all(cost <= limit[:, None], axis=0)

    rows: list[dict[str, float]] = [best]
    for dim in dims:
        for stepped in dim.steps(best[dim.name]):
            rows.append({**best, dim.name: stepped})
    limit = channel.cost({k: np.array([best[k]]) for k in keys}, 1, cfg.check_dt,
                         per_log=True)[:, 0] * (1.0 + cfg.tol) + 1e-9
    flat = within(rows)[1:]
    status = {name: FITTED for name in names}
    loose = []
    for i, dim in enumerate(dims):
        up_flat, down_flat = flat[2 * i], flat[2 * i + 1]
        if (up_flat and down_flat) or (dim.name in LIMITS and up_flat):
            loose.append(dim.name)
    if not loose:
        return best, status

    def moved(values: dict[str, float], which: list[str]) -> dict[str, float]:
        out = dict(values)
        for name in which:                 # accel before decel: "as accel" sees the new accel
            out[name] = prior_value(prior, name, out)
        return out

    # All of them at their priors at once; else one at a time, in field order (an accel limit
    # before its decel limit, whose prior may be "as accel").
    joint = moved(best, loose)
    if within([joint])[0]:
        return joint, {**status, **{name: PRIOR for name in loose}}
    values = dict(best)
    for name in loose:
        target = prior_value(prior, name, values)
        if not math.isfinite(target):
            target = by_name[name].hi      # "no limit": as far up as the search looked
        # From the fitted value towards the prior, in steps: the nearest to the prior the log
        # allows (for a limit the log bounds from below: the lowest it allows, a cautious model).
        dim = by_name[name]
        fractions = np.linspace(0.0, 1.0, 13)[1:]
        if dim.log:
            ladder = values[name] * (target / values[name]) ** fractions
        else:
            ladder = values[name] + (target - values[name]) * fractions
        ok = np.flatnonzero(within([{**values, name: float(v)} for v in ladder]))
        if len(ok):
            values[name] = float(ladder[ok[-1]])
            status[name] = PRIOR if ok[-1] == len(ladder) - 1 else BOUND
        else:
            status[name] = BOUND
    return values, status


# The scan around each fitted value (:func:`how_determined`): up to x2 and /2 for lags and limits,
# +-0.1 s for delays, +-0.3 for the couplings, in this many steps each way (quadratically
# spaced: the first 1 % of the span).
SCAN_STEPS = 10


def _scan(dim: Dim, value: float) -> np.ndarray:
    """Values around ``value``, from the lowest to the highest, ``value`` itself in the middle."""
    k = np.linspace(-1.0, 1.0, 2 * SCAN_STEPS + 1)
    k = np.sign(k) * k * k            # fine near the value (1 % of the span), coarse far off
    if dim.name in DELAYS:
        return np.maximum(value + 0.1 * k, 0.0)
    if dim.name in COUPLINGS:
        return np.clip(value + 0.3 * k, 0.0, 1.0)
    if dim.name == YAW_OVERSHOOT:
        return np.clip(value + 0.3 * k, dim.lo, dim.hi)
    return value * 2.0 ** k


def how_determined(channel: Objective, dims: list[Dim], values: dict[str, float],
                   status: dict[str, str], cfg: Search) -> dict[str, Determined]:
    """:class:`Determined` for each fitted parameter of the channel, from one batch of model
    runs: each parameter alone scanned (:func:`_scan`), every log held to ``tol`` of its RMS."""
    fitted = [dim for dim in dims if status[dim.name] == FITTED]
    if not fitted:
        return {}
    keys = list(values)
    rows = [dict(values)]
    for dim in fitted:
        rows += [{**values, dim.name: float(v)} for v in _scan(dim, values[dim.name])]
    cost = channel.cost({k: np.array([row[k] for row in rows]) for k in keys}, len(rows),
                        cfg.check_dt, per_log=True)            # (logs, rows)
    limit = cost[:, :1] * (1.0 + cfg.tol) + 1e-9
    out = {}
    width = 2 * SCAN_STEPS + 1
    for i, dim in enumerate(fitted):
        block = cost[:, 1 + i * width: 1 + (i + 1) * width]
        scanned = _scan(dim, values[dim.name])
        ok = np.all(block <= limit, axis=0)
        lo_i = hi_i = SCAN_STEPS
        while lo_i > 0 and ok[lo_i - 1]:
            lo_i -= 1
        while hi_i < width - 1 and ok[hi_i + 1]:
            hi_i += 1
        lo = -math.inf if lo_i == 0 and scanned[0] < values[dim.name] else float(scanned[lo_i])
        hi = math.inf if hi_i == width - 1 and scanned[-1] > values[dim.name] \
            else float(scanned[hi_i])
        seen = tuple(int(k) for k in np.flatnonzero(np.any(block > limit, axis=1)))
        out[dim.name] = Determined(lo, hi, seen)
    return out


def prior_value(prior: RoverParams, name: str, values: dict[str, float]) -> float:
    """A field's prior as a number; a decel limit left at "as accel" (None) takes the accel
    value in ``values`` (ArduPilot's ATC_DECEL_MAX 0 means the same limit both ways)."""
    value = getattr(prior, name)
    if value is None and name == "max_decel":
        value = values.get("max_accel", prior.max_accel)
    elif value is None and name == "max_yaw_decel":
        value = values.get("max_yaw_accel", prior.max_yaw_accel)
    elif value is None and name == "w_c_yaw":
        value = prior.w_c
    return float(value)
