"""The search space: the robust search's own dimensions on top of :mod:`companion.sim.tuning`'s,
its seeds, random draws and perturbations, and a candidate as gains and as a tracker."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from ...core.filter import FilterGains
from ...core.limits import Limits
from ...core.pzc import PZCGains, PZCTracker
from ...core.signals import Num
from ..plant import RoverParams
from ..tuning import Candidates, perturb, random_candidates

# The robust search's own dimensions (log-uniform ranges; tuning.RANGES / FLAGS are unchanged):
# accel_ff_turn in seconds; the braking accelerations as factors of the vehicle's scale
# (brake_scales: its speed / turn-rate deceleration), so one range fits any vehicle.
EXTRA_RANGES = {
    "accel_ff_turn": (0.002, 1.0),
    "brake_accel_k": (0.05, 4.0),
    "brake_yaw_accel_k": (0.1, 4.0),
}
EXTRA_FLAGS = ("split_accel_ff", "use_brake", "use_brake_yaw")
# On a late speed loop (RobustConfig.predict_delay > 0) two more dimensions: whether the speed
# is predicted (core.predict) and how far ahead, as a share of the identified delay. Seeded at
# half of it: the whole delay tracks the fastest reference best and the slow ones worst, half
# of it nearly as well at the fastest and best at the slow ones (docs/design/robust-tuning.md).
PREDICT_RANGE = (0.1, 1.0)
PREDICT_SEED = 0.5
# Braking scale when the vehicle has no identified limit (an infinite decel).
DEFAULT_BRAKE_SCALE = (5.0, 10.0)            # m/s^2, rad/s^2


def brake_scales(vehicle: RoverParams) -> tuple[float, float]:
    """The accelerations the braking factors multiply: the identified vehicle's speed and
    turn-rate decelerations (the braking curve is about stopping in time), or
    :data:`DEFAULT_BRAKE_SCALE` where the vehicle has no limit."""
    out = []
    for value, default in ((vehicle.decel, DEFAULT_BRAKE_SCALE[0]),
                           (vehicle.yaw_decel, DEFAULT_BRAKE_SCALE[1])):
        v = float(np.min(value))
        out.append(v if math.isfinite(v) and v > 0 else default)
    return out[0], out[1]

def extension_values(cands: Candidates, scales: tuple[float, float],
                     predict_delay: float = 0.0) -> dict[str, np.ndarray]:
    """accel_ff_turn (s; NaN: not split), brake_accel, brake_yaw_accel, predict_s (0: off) per
    candidate, from the extra parameters and flags (absent: every extension off, the old
    search); ``predict_delay``: what the share predict_k is of."""
    n = len(cands)
    p, f = cands.params, cands.flags
    off = np.zeros(n)
    accel_ff = np.where(f["use_accel_ff"] > 0.5, p["accel_ff"], 0.0)
    split = f.get("split_accel_ff", off) > 0.5
    return {
        "accel_ff_turn": np.where(split, p.get("accel_ff_turn", accel_ff), np.nan),
        "brake_accel": np.where(f.get("use_brake", off) > 0.5,
                                p.get("brake_accel_k", off) * scales[0], 0.0),
        "brake_yaw_accel": np.where(f.get("use_brake_yaw", off) > 0.5,
                                    p.get("brake_yaw_accel_k", off) * scales[1], 0.0),
        "predict_s": np.where(f.get("use_predict", off) > 0.5,
                              p.get("predict_k", off) * predict_delay, 0.0),
    }


def tracker(cands: Candidates, repeat: int, limits: Limits,
            scales: tuple[float, float] = DEFAULT_BRAKE_SCALE,
            law: Mapping[str, Any] | None = None, predict_delay: float = 0.0) -> PZCTracker:
    """The candidates as one tracker of ``len(cands) * repeat`` vehicles, each candidate's
    gains ``repeat`` times, with the ``law`` settings they share (RobustConfig.law_settings)."""
    p, f = cands.params, cands.flags
    rep = lambda a: np.repeat(a, repeat)  # noqa: E731
    separate = f["separate_yaw"] > 0.5
    accel_ff = np.where(f["use_accel_ff"] > 0.5, p["accel_ff"], 0.0)
    ext = extension_values(cands, scales, predict_delay)
    turn = ext["accel_ff_turn"]
    any_split = bool(np.any(np.isfinite(turn)))
    return PZCTracker(
        FilterGains(rep(p["k_df"]), rep(p["lambda_f"])),
        PZCGains(rep(p["k_dc"]), rep(p["lambda_c"]),
                 k_dc_yaw=rep(np.where(separate, p["k_dc_yaw"], p["k_dc"])),
                 lambda_c_yaw=rep(np.where(separate, p["lambda_c_yaw"], p["lambda_c"])),
                 velocity_ff=rep(f["velocity_ff"]), heading_rate_ff=rep(f["heading_rate_ff"]),
                 accel_ff=rep(accel_ff),
                 # not split = the normal part previewed by accel_ff itself
                 accel_ff_turn=rep(np.where(np.isfinite(turn), turn, accel_ff)) if any_split
                 else None,
                 brake_accel=rep(ext["brake_accel"]) if np.any(ext["brake_accel"] > 0) else 0.0,
                 brake_yaw_accel=(rep(ext["brake_yaw_accel"])
                                  if np.any(ext["brake_yaw_accel"] > 0) else 0.0),
                 predict_s=rep(ext["predict_s"]) if np.any(ext["predict_s"] > 0) else 0.0,
                 **(law or {})),
        limits, n=len(cands) * repeat)


def candidate_gains(cands: Candidates, i: int,
                    scales: tuple[float, float] = DEFAULT_BRAKE_SCALE,
                    predict_delay: float = 0.0) -> tuple[FilterGains, PZCGains]:
    """Candidate ``i`` as gains (what a gains file stores): :meth:`Candidates.gains` plus the
    extensions of this search, in absolute units (the braking factors times ``scales``, the
    prediction's share times ``predict_delay``)."""
    fg, pg = cands.gains(i)
    ext = {k: float(v[i]) for k, v in extension_values(cands, scales, predict_delay).items()}
    return fg, replace(pg, accel_ff_turn=None if math.isnan(ext["accel_ff_turn"])
                       else ext["accel_ff_turn"],
                       brake_accel=ext["brake_accel"], brake_yaw_accel=ext["brake_yaw_accel"],
                       predict_s=ext["predict_s"])


def seeds(vehicle: RoverParams | None = None) -> Candidates:
    """Starting points: gentle PI gains with both feed-forwards, a few bandwidths apart, with
    and without acceleration feed-forward, and the paper's own gains (no lead, no extension);
    then firmer PI gains with every extension on: the speed preview at the vehicle's speed
    channel delay + lag (0.3 s without a vehicle), the turn preview near zero or at the turn
    channel's delay + lag, the braking curves at the vehicle's own decelerations (factor 1) or
    below (0.2 speed, 0.5 turn rate: where the searches on an ArduPilot rover ended)."""
    rows = []
    for k_dc, lambda_c in ((0.2, 0.3), (0.4, 0.8), (1.0, 1.0), (2.0, 2.0)):
        for k_yaw, l_yaw in ((1.0, 1.0), (2.0, 2.0)):
            rows.append((500, 40, k_dc, lambda_c, k_yaw, l_yaw, 0.05, 0.05, 1, 1, 1, 1, 0, 0))
            rows.append((500, 40, k_dc, lambda_c, k_yaw, l_yaw, 0.3, 0.05, 1, 1, 1, 1, 1, 0))
    rows.append((1000, 120, 5, 12, 5, 12, 0.05, 0.05, 1, 0, 0, 0, 0, 0))
    extra = [(0.01, 1.0, 1.0, 0, 0, 0)] * len(rows)
    speed_preview, turn_preview = 0.3, 0.05
    if vehicle is not None:
        speed_preview = _finite(vehicle.speed_delay, 0.0) + 1.0 / _finite(vehicle.w_c, 20.0)
        turn_preview = _finite(vehicle.yaw_delay, 0.0) + 1.0 / _finite(vehicle.yaw_bandwidth, 20.0)
    for k_dc, lambda_c in ((0.3, 0.3), (0.7, 0.6)):
        for k_yaw, l_yaw in ((1.0, 1.6), (2.0, 2.0)):
            for turn, brake, brake_yaw in ((0.005, 0.2, 0.5), (turn_preview, 1.0, 1.0)):
                rows.append((1000, 250, k_dc, lambda_c, k_yaw, l_yaw, speed_preview, 0.05, 1,
                             1, 1, 1, 1, 0))
                extra.append((turn, brake, brake_yaw, 1, 1, 1))
    a = np.array(rows, dtype=float)
    e = np.array(extra, dtype=float)
    names = ("k_df", "lambda_f", "k_dc", "lambda_c", "k_dc_yaw", "lambda_c_yaw", "accel_ff",
             "lead_tau", "lead_max_gain")
    flags = ("velocity_ff", "heading_rate_ff", "separate_yaw", "use_accel_ff", "use_lead")
    params = {k: a[:, i] for i, k in enumerate(names)}
    params.update({k: e[:, i] for i, k in enumerate(EXTRA_RANGES)})
    flag_values = {k: a[:, len(names) + i] for i, k in enumerate(flags)}
    flag_values.update({k: e[:, len(EXTRA_RANGES) + i] for i, k in enumerate(EXTRA_FLAGS)})
    return Candidates(params, flag_values)


def _finite(value: Num, default: float) -> float:
    v = float(np.mean(value))
    return v if math.isfinite(v) and v > 0 else default


def _no_lead(c: Candidates) -> Candidates:
    c.flags["use_lead"] = np.zeros(len(c))
    return c


def drawn(rng: np.random.Generator, n: int, predict: bool = False) -> Candidates:
    """:func:`companion.sim.tuning.random_candidates` plus this search's own dimensions (with
    ``predict``, the speed prediction's too, drawn last: the others' draws stay as they were)."""
    c = random_candidates(rng, n)
    for k, (lo, hi) in EXTRA_RANGES.items():
        c.params[k] = np.exp(rng.uniform(math.log(lo), math.log(hi), n))
    for k in EXTRA_FLAGS:
        c.flags[k] = rng.integers(0, 2, n).astype(float)
    if predict:
        lo, hi = PREDICT_RANGE
        c.params["predict_k"] = np.exp(rng.uniform(math.log(lo), math.log(hi), n))
        c.flags["use_predict"] = rng.integers(0, 2, n).astype(float)
    return _no_lead(c)


def perturbed(rng: np.random.Generator, parents: Candidates, n: int, sigma: float,
              predict: bool = False) -> Candidates:
    """:func:`companion.sim.tuning.perturb` (which carries the extra dimensions along with each
    child's parent) plus the same log-normal steps and flag flips on the extra dimensions (with
    ``predict``, the speed prediction's too)."""
    child = perturb(rng, parents, n, sigma)
    ranges = {**EXTRA_RANGES, **({"predict_k": PREDICT_RANGE} if predict else {})}
    flags = EXTRA_FLAGS + (("use_predict",) if predict else ())
    for k, (lo, hi) in ranges.items():
        child.params[k] = np.clip(child.params[k] * np.exp(sigma * rng.standard_normal(n)), lo, hi)
    for k in flags:
        flip = rng.random(n) < 0.1
        child.flags[k] = np.where(flip, 1.0 - child.flags[k], child.flags[k])
    return _no_lead(child)


def predict_seeds(start: Candidates) -> Candidates:
    """The seeds without the prediction, then the firmer ones (every extension on) again with
    it at PREDICT_SEED of the delay."""
    n = len(start)
    start.params["predict_k"] = np.full(n, PREDICT_SEED)
    start.flags["use_predict"] = np.zeros(n)
    firm = np.flatnonzero(start.flags["use_brake"] > 0.5)
    again = start.take(firm)
    again.flags["use_predict"] = np.ones(len(firm))
    return Candidates.concat([start, again])
