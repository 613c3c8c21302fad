"""The fit: the vehicle model's inner loops against a log's setpoints and measured response.

Pure: arrays in (:class:`Series`: setpoints held on the measurement times, measured signed
speed along the heading and turn rate), parameters and RMS out; no file, no clock.

The model is :func:`companion.sim.response.respond` (per channel: delay -> clamp -> rate limit
-> first-order lag, and the speed clamp shrinking with the turn rate), so the model fitted is
the model the simulations and the bundled plant run; the search steps one channel at a time
(:mod:`companion.ident.channels`, respond's model step for step, at half the cost) and the
figures reported come from ``respond`` itself. The turn-rate channel is fitted first
(delay, lag, clamp, accel, decel, and ``speed_turn_coupling``: the clamp it loses with speed,
driven by the *measured* speed, so it needs no speed model yet; for a car, a prior with a
turning radius, the radius too, and the lateral-acceleration limit as the prior has it), then the speed channel (delay,
lag, clamp, accel, decel, ``turn_speed_coupling``) with the turn rate the fitted turn-rate model
produces. The turn-rate coupling is a share of the clamp at top speed, and top speed is fitted
after it: the turn-rate search measures the speed against a fixed scale (the prior's top speed,
else the fastest measured), and the share is rescaled to the fitted top speed at the end (the
same loss per m/s below top speed).

The search over each channel's parameters is :mod:`companion.ident.search`'s (a cross-entropy
search), its objective :mod:`companion.ident.objective`'s; what the log does not determine moves
to its prior (:mod:`companion.ident.determinacy`). The log itself arrives as a
:class:`~companion.ident.series.Series`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from .. import profiles
from ..sim.plant import RoverParams
from ..sim.response import respond
from . import channels
from .determinacy import FITTED, PRIOR, Determined, how_determined, prior_value, settle
from .objective import Objective
from .priors import COURSE_FIELDS, SPEED_FIELDS, YAW_FIELDS
from .search import TURN_COUPLING, TURN_RADIUS, Search, minimise, search_space
from .series import Series, with_course_loop

MIN_COMMAND = 1e-3        # a channel whose setpoints never exceed this was not driven at all

DEFAULT_SEARCH = Search()


@dataclass(frozen=True)
class Fit:
    params: RoverParams
    speed_rms: float               # m/s, simulated minus measured, over the series
    yaw_rate_rms: float            # rad/s
    status: dict[str, str] = field(default_factory=dict)    # field -> FITTED / PRIOR / BOUND
    evaluations: int = 0           # model runs (one per parameter set)
    determined: dict[str, Determined] = field(default_factory=dict)   # FITTED fields only

    @property
    def undetermined(self) -> tuple[str, ...]:
        """The fitted fields the log did not determine (left at the prior, or only bounded)."""
        return tuple(name for name, s in self.status.items() if s != FITTED)


def _speed_scale(series: Series, prior: RoverParams) -> float:
    """The top speed the turn-rate search measures the coupling against (module docstring)."""
    top = float(prior.max_speed)
    if math.isfinite(top) and top > 0:
        return top
    return max(float(np.max(np.abs(series.speed))), 0.1)


def _fit_channel(series: Series, base: RoverParams, prior: RoverParams, fields: tuple[str, ...],
                 which: int, cfg: Search, rng: np.random.Generator,
                 extra: tuple[str, ...] = (), wide_extra: bool = False,
                 ) -> tuple[dict[str, float], dict[str, str], int, dict[str, Determined]]:
    """One channel's search over ``fields``; then, with ``extra``, a second search over all
    of them from the first's best (the extras at their priors), kept only when it explains
    the log better by more than ``tol`` (so a vehicle without what the extras describe fits
    exactly as without them, and the first search keeps its budget for the usual fields).
    ``wide_extra``: that second search is a whole one (random start, ``cfg.schedule``), for
    extras the first search's fields can imitate from far away (a slow lag for a late tail)."""
    channel = Objective(series, base, which, _speed_scale(series, prior))
    commands = series.yaw_rate_cmd if which == 1 else series.speed_cmd
    start: dict[str, float] = {}
    for name in fields + extra:
        start[name] = prior_value(prior, name, start)
    if float(np.max(np.abs(commands))) < MIN_COMMAND:
        # Never driven: nothing in the log speaks to this channel.
        return start, {name: PRIOR for name in fields + extra}, 0, {}
    dims = search_space(fields, series)
    u0 = np.array([dim.unit(start[dim.name]) for dim in dims])
    u_best, cost = minimise(channel, dims, u0, cfg, rng)
    best = {dim.name: float(dim.value(u_best[i])) for i, dim in enumerate(dims)}
    if extra:
        wide = search_space(fields + extra, series)
        # (a whole search starts from the priors: the first's best sits in the valley the
        # extras' effect was imitated in, a slow lag for a late tail, and holds a chain there)
        u1 = np.array([dim.unit((start if wide_extra else {**start, **best})[dim.name])
                       for dim in wide])
        u_more, more = minimise(channel, wide, u1,
                               replace(cfg, schedule=WIDE_SCHEDULE, shrink=WIDE_SHRINK,
                                       polish=WIDE_POLISH) if wide_extra
                               else replace(cfg, schedule=EXTRA_SCHEDULE), rng)
        if more < cost * (1.0 - cfg.tol):
            best = {dim.name: float(dim.value(u_more[i])) for i, dim in enumerate(wide)}
        else:
            best.update({name: start[name] for name in extra})
        dims = wide
    values, status = settle(channel, dims, best, prior, cfg)
    still = [dim for dim in dims if status[dim.name] == FITTED]
    if still and len(still) < len(dims):
        # What moved to its prior changes what the rest are seen to do (a coupling that bit
        # only under a low clamp the search had found): look at those once more.
        values, again = settle(channel, still, values, prior, cfg)
        status.update(again)
    determined = how_determined(channel, dims, values, status, cfg)
    return values, status, channel.evaluations, determined


# The second search of a channel with extra fields: from the first's best, narrower each round
# (the first round keeps the best among random sets, the rest sample around it).
EXTRA_SCHEDULE = ((60, 0.02),) + ((60, 0.02),) * 6 + ((40, 0.01),)
# ... and a whole second search (``wide_extra``), longer than the first: two more dimensions
WIDE_SCHEDULE = ((1000, 0.02),) + ((300, 0.02),) * 20 + ((60, 0.01),)
WIDE_SHRINK, WIDE_POLISH = 0.8, 8


def _derived(params: RoverParams, series: Series) -> Series:
    return with_course_loop(series, float(params.course_gain), float(params.min_turn_radius),
                            float(params.max_yaw_rate))


def rms(params: RoverParams, series: Series, dt: float = 0.01) -> tuple[float, float]:
    """(speed RMS m/s, turn-rate RMS rad/s) of the model ``params`` against a series."""
    series = _derived(params, series)
    v, w = respond(params, series.t, series.speed_cmd, series.yaw_rate_cmd, 1, dt,
                   v0=float(series.speed[0]), omega0=float(series.yaw_rate[0]))
    return (float(np.sqrt(np.mean((v[:, 0] - series.speed) ** 2))),
            float(np.sqrt(np.mean((w[:, 0] - series.yaw_rate) ** 2))))


def simulate(params: RoverParams, series: Series, dt: float = 0.01
             ) -> tuple[np.ndarray, np.ndarray]:
    """The model's speed and turn rate on the series' times (for plots)."""
    series = _derived(params, series)
    v, w = respond(params, series.t, series.speed_cmd, series.yaw_rate_cmd, 1, dt,
                   v0=float(series.speed[0]), omega0=float(series.yaw_rate[0]))
    return v[:, 0], w[:, 0]


# (course gain, turning radius) factors tried around the prior for a velocity-vector log
COURSE_GAIN_STEPS = (0.35, 0.5, 0.7, 1.0, 1.4, 2.0, 2.8)
TURN_RADIUS_STEPS = (0.5, 0.7, 0.85, 1.0, 1.2, 1.45, 1.8)
FINE_GAIN_STEPS = (0.6, 0.7, 0.8, 0.9, 1.0, 1.12, 1.25, 1.4, 1.6)
FINE_RADIUS_STEPS = (0.8, 0.9, 1.0, 1.1, 1.2)


def _course_rms(series: Series, params: RoverParams, dt: float) -> float:
    s = _derived(params, series)
    out, _ = channels.turn_rate(s.t, s.yaw_rate_cmd, 1, dt, float(s.yaw_rate[0]),
                                params.yaw_delay, params.yaw_bandwidth, params.max_yaw_rate,
                                params.max_yaw_accel, params.yaw_decel)
    return float(np.sqrt(np.mean((out[:, 0] - s.yaw_rate) ** 2)))


def _fit_course(series: Series, params: RoverParams, prior: RoverParams, cfg: Search,
                gain_steps=COURSE_GAIN_STEPS, radius_steps=TURN_RADIUS_STEPS,
                ) -> tuple[dict[str, float], dict[str, str]]:
    """PX4's course gain and the turning radius on a grid around the prior, with the turn-rate
    channel as fitted (the grid's best; determinacy as in :func:`companion.ident.determinacy.settle`: a factor of 1.4 or
    so that leaves the RMS within ``tol`` either way does not count as seen)."""
    k0, r0 = float(prior.course_gain), float(prior.min_turn_radius)
    radii = [r0 * f for f in radius_steps] if r0 > 0 else [0.0]
    grid = [(k0 * a, r) for a in gain_steps for r in radii]
    costs = [_course_rms(series, params.with_(course_gain=k, min_turn_radius=r), cfg.check_dt)
             for k, r in grid]
    best = int(np.argmin(costs))
    k, r = grid[best]
    limit = costs[best] * (1.0 + cfg.tol) + 1e-9
    status = {}
    for name, values in (("course_gain", {kk for kk, rr in grid if rr == r and kk != k}),
                         ("min_turn_radius", {rr for kk, rr in grid if kk == k and rr != r})):
        near = [costs[i] for i, (kk, rr) in enumerate(grid)
                if (kk if name == "course_gain" else rr) in values
                and (rr == r if name == "course_gain" else kk == k)]
        status[name] = FITTED if near and min(near) > limit else PRIOR
    fitted = {"course_gain": k if status["course_gain"] == FITTED else k0,
              "min_turn_radius": r if status["min_turn_radius"] == FITTED else r0}
    return fitted, status


def fit(series: Series, prior: RoverParams, search: Search = DEFAULT_SEARCH,
        progress: Callable[[str], None] = lambda text: None) -> Fit:
    """Fit the turn-rate channel, then the speed channel (module docstring). A velocity-vector
    series (PX4) first takes its turn-rate command from the prior's course loop; after the
    channels, the course gain and turning radius are fitted on a grid and the turn-rate
    channel once more with them."""
    if series.vector:
        # (the first pass only seeds the course loop's grid: no overshoot search in it)
        first = _fit_channels(_derived(prior, series), prior, search, progress, overshoot=False)
        progress("course loop")
        course, course_status = _fit_course(series, first.params, prior, search)
        again_prior = prior.with_(**course)
        second = _fit_channels(_derived(again_prior, series), again_prior, search, progress)
        # once more, finer, with the channel fitted to the course loop found (the first
        # channel fit, made with the prior's loop, may have absorbed part of its error)
        fine, fine_status = _fit_course(series, second.params.with_(**course),
                                        second.params.with_(**course), search,
                                        FINE_GAIN_STEPS, FINE_RADIUS_STEPS)
        for name in COURSE_FIELDS:
            if course_status[name] == FITTED:
                course[name] = fine[name]
        params = second.params.with_(**course)
        speed_rms, yaw_rms = rms(params, series, search.dt)
        return Fit(params, speed_rms, yaw_rms, {**second.status, **course_status},
                   first.evaluations + second.evaluations, second.determined)
    return _fit_channels(series, prior, search, progress)


def _fit_channels(series: Series, prior: RoverParams, search: Search,
                  progress: Callable[[str], None], overshoot: bool = True) -> Fit:
    rng = np.random.default_rng(search.seed)
    progress("turn-rate channel")
    yaw_fields: tuple[str, ...] = YAW_FIELDS[:-2]
    car = not series.vector and not profiles.steering_of_model(prior).turns_in_place
    if car:
        # A car driven by turn-rate setpoints (ArduPilot's Ackermann rover, the steering kind
        # its prior describes): its turning radius clamps the turn rate by the measured speed,
        # so the turn-rate channel fits it.
        yaw_fields = yaw_fields + (TURN_RADIUS,)
    # The rate loop's two time scales (a feed-forward that over- or under-drives the steering,
    # the integrator doing the rest): searched after the usual fields, for turn-rate setpoints
    # only (PX4's course loop is fitted on its own grid), and not for a car: at full lock its
    # turn rate is the steering's |v| / R whatever the rate loop asks, while the model's share
    # acts past the clamp, so the two trade against each other (on SITL's car the radius came
    # out 10 % short: docs/calibrate-and-identify.md).
    yaw_extra = YAW_FIELDS[-2:] if overshoot and not series.vector and not car else ()
    yaw, yaw_status, n_yaw, yaw_det = _fit_channel(series, prior, prior, yaw_fields, 1,
                                                    search, rng, extra=yaw_extra,
                                                    wide_extra=True)
    progress("speed channel")
    base = prior.with_(**yaw)
    # the speed loop's overshoot: searched only once the usual fields are (the second search)
    speed, speed_status, n_speed, speed_det = _fit_channel(
        series, base, prior, SPEED_FIELDS[:-2], 0, search, rng,
        extra=SPEED_FIELDS[-2:] if overshoot else ())
    determined = {**yaw_det, **speed_det}
    params = base.with_(**speed)
    if yaw_status[TURN_COUPLING] != PRIOR:
        # The share was of the search's speed scale; the model's is of the fitted top speed.
        scale = _speed_scale(series, prior)
        top = float(params.max_speed)
        if math.isfinite(top) and top != scale:
            share = float(np.clip(yaw[TURN_COUPLING] * top / scale, 0.0, 1.0))
            params = params.with_(**{TURN_COUPLING: share})
            if TURN_COUPLING in determined:
                d = determined[TURN_COUPLING]
                determined[TURN_COUPLING] = replace(d, lo=d.lo * top / scale,
                                                    hi=d.hi * top / scale)
    speed_rms, yaw_rms = rms(params, series, search.dt)
    return Fit(params, speed_rms, yaw_rms, {**yaw_status, **speed_status}, n_yaw + n_speed + 1,
               determined)
