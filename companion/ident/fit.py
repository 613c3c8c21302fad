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

Search (per channel): every parameter is mapped onto [0, 1] (log scale for lags and limits,
linear for delays and the coupling share); a uniform random population plus the prior, then
rounds that sample around the best so far and around the elite's mean with the elite's
covariance, capped by a width that shrinks each round (a cross-entropy search with full
covariance, so parameters that trade against each other are followed along their valley), three
independent chains side by side (a delay traded against a lag can have two valleys). One round
is one vectorised simulation of all chains' populations; the rounds on a 20 ms grid (ArduPilot's
50 Hz loop; on 40 ms the grid's own error is above the noise), the last on 10 ms. The
objective is the RMS of simulated minus measured output over the log.

What the log does not determine: around the best, each parameter is moved by a clear step
(lags and limits x1.5 and /1.5, delays 50 ms, the couplings 0.15). If the RMS moves by less than
``tol`` (2 %) either way, or, for a clamp or a rate limit, when raising it changes nothing (the
limit never bound: the log gives only a lower bound), the parameter is *undetermined*: it moves
towards its prior (:mod:`companion.ident.priors`) as far as the log allows (the RMS within
``tol``): all the way (status ``prior``), or part of the way when the log contradicts the prior
(status ``bound``: e.g. a top speed the log shows is at least 4.3 m/s against a prior of 4 ends
at the lowest value the log allows, a cautious model).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..sim.plant import RoverParams
from ..sim.response import respond
from . import channels
from .priors import COURSE_FIELDS, SPEED_FIELDS, YAW_FIELDS

FITTED, PRIOR, BOUND = "fitted", "prior", "bound"
LIMITS = {"max_speed", "max_accel", "max_decel", "max_yaw_rate", "max_yaw_accel", "max_yaw_decel"}
LAGS = {"w_c", "w_c_yaw"}
DELAYS = {"speed_delay", "yaw_delay"}
COUPLING = "turn_speed_coupling"
TURN_COUPLING = "speed_turn_coupling"
COUPLINGS = {COUPLING, TURN_COUPLING}
OVERSHOOT = "speed_overshoot"     # a share, stepped as the couplings are
YAW_OVERSHOOT = "yaw_overshoot"   # a signed share (the rate loop's two time scales)
TURN_RADIUS = "min_turn_radius"   # a car's (speed / turn-rate setpoints): fitted in its channel
MIN_COMMAND = 1e-3        # a channel whose setpoints never exceed this was not driven at all


@dataclass(frozen=True)
class Series:
    """One log as the fit sees it, on the measurement times ``t`` (s, increasing): the setpoint
    in force at each sample (held since it was sent) and the measured response."""

    t: np.ndarray
    speed_cmd: np.ndarray          # m/s
    yaw_rate_cmd: np.ndarray       # rad/s
    speed: np.ndarray              # measured signed speed along the heading, m/s
    yaw_rate: np.ndarray           # measured turn rate, rad/s
    starts: tuple[int, ...] = (0,)     # first sample of each log, when several are joined
    # PX4 (velocity vectors): the course atan2(u_p) in force and the measured heading, rad;
    # ``yaw_rate_cmd`` is then derived (:func:`with_course_loop`)
    course_cmd: np.ndarray | None = None
    yaw: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.t)
        if n < 2 or any(len(a) != n for a in (self.speed_cmd, self.yaw_rate_cmd, self.speed,
                                               self.yaw_rate)):
            raise ValueError("a series needs >= 2 samples and arrays of one length")

    @property
    def segments(self) -> list[slice]:
        """Each joined log's samples (one slice for a single log)."""
        ends = self.starts[1:] + (len(self.t),)
        return [slice(a, b) for a, b in zip(self.starts, ends, strict=True)]

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def vector(self) -> bool:
        """Velocity-vector setpoints (PX4): the turn-rate command comes from the course loop."""
        return self.course_cmd is not None


def with_course_loop(series: Series, course_gain: float, min_turn_radius: float,
                     max_yaw_rate: float = math.inf) -> Series:
    """The series with the turn-rate command PX4's course loop makes of its velocity vectors
    (:meth:`companion.sim.plant.RoverModel.step_vector`), on the *measured* heading and speed:
    ``clip(K wrap(course - yaw), +-max_yaw_rate, +-|v| / R_min)``. The turn-rate channel is
    then fitted as ArduPilot's (series-parallel: the loop closed on what was measured)."""
    if series.course_cmd is None:   # (not series.vector)
        return series
    err = np.remainder(series.course_cmd - series.yaw + math.pi, 2.0 * math.pi) - math.pi
    cmd = np.clip(course_gain * err, -max_yaw_rate, max_yaw_rate)
    cmd = np.where(series.speed_cmd > 0, cmd, 0.0)          # a zero vector: no course at all
    if min_turn_radius > 0:
        top = np.abs(series.speed) / min_turn_radius
        cmd = np.clip(cmd, -top, top)
    return replace(series, yaw_rate_cmd=cmd)


def join(parts: Sequence[Series]) -> Series:
    """Several logs as one series: each next part starts one sample step after the previous
    ends, so one model is fitted to all of them (a manoeuvre and a tracking flight: the regimes
    that each determine best). Sound because every part cut by
    :func:`companion.ident.data.series_from_flight` begins at rest before its first moving
    setpoint and ends at rest after its stop: the model's state carries nothing across a seam."""
    if len(parts) == 1:
        return parts[0]
    times: list[np.ndarray] = []
    offset = 0.0
    for i, part in enumerate(parts):
        step = float(np.median(np.diff(part.t)))
        if i > 0:
            offset = times[-1][-1] + step - float(part.t[0])
        times.append(part.t + offset)
    vector = {part.vector for part in parts}
    if len(vector) > 1:
        raise ValueError("speed / turn-rate logs (ArduPilot) and velocity-vector logs (PX4) "
                         "cannot be fitted as one vehicle")
    extra = ("course_cmd", "yaw") if vector == {True} else ()
    starts = tuple(int(k) for k in np.cumsum([0] + [len(part.t) for part in parts[:-1]]))
    joined = {name: np.concatenate([getattr(part, name) for part in parts])
              for name in ("t", "speed_cmd", "yaw_rate_cmd", "speed", "yaw_rate") + extra}
    joined["t"] = np.concatenate(times)
    return Series(**joined, starts=starts)


@dataclass(frozen=True)
class Search:
    """How hard to look. The budget is counted in rounds (numpy's step loop cost about as much
    for 10 sets as for 300; compiled, a set costs about 30 ns a grid step, so a round of 300
    sets over a 90 s log at 20 ms is some 0.04 s plus the clamps' arrays): ``schedule`` is one (population
    per chain, grid step) per round, the first uniform, the rest around the best; ``dt`` is the
    grid of the final figures."""

    # (the first round's 200 per chain: with six parameters per channel, 150 left a chain in
    # the delay-against-lag valley's far end now and then)
    schedule: tuple[tuple[int, float], ...] = (
        ((200, 0.02),) + ((100, 0.02),) * 10 + ((40, 0.01),))
    chains: int = 3                # independent searches, evaluated in the same calls
    check_dt: float = 0.02         # grid of the determinacy check
    dt: float = 0.01
    shrink: float = 0.72           # search width (unit box) x this per round, from 0.3
    tol: float = 0.02              # relative RMS change below which a parameter is not seen
    seed: int = 0
    polish: int = 0                # rounds of coordinate polishing after the search (at most)


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


@dataclass(frozen=True)
class _Dim:
    name: str
    lo: float
    hi: float
    log: bool

    def value(self, u: np.ndarray) -> np.ndarray:
        u = np.clip(u, 0.0, 1.0)
        if self.log:
            return self.lo * (self.hi / self.lo) ** u
        return self.lo + (self.hi - self.lo) * u

    def unit(self, value: float) -> float:
        if not math.isfinite(value):
            return 1.0
        if self.log:
            share = math.log(max(value, 1e-12) / self.lo) / math.log(self.hi / self.lo)
            return float(np.clip(share, 0.0, 1.0))
        return float(np.clip((value - self.lo) / (self.hi - self.lo), 0.0, 1.0))

    def steps(self, value: float) -> tuple[float, float]:
        """(raised, lowered): a change the log should show if it determines this parameter."""
        if self.name in DELAYS:
            return value + 0.05, max(value - 0.05, 0.0)
        if self.name in COUPLINGS or self.name == OVERSHOOT:
            return min(value + 0.15, 1.0), max(value - 0.15, 0.0)
        if self.name == YAW_OVERSHOOT:
            return min(value + 0.15, self.hi), max(value - 0.15, self.lo)
        return value * 1.5, value / 1.5


def _dims(fields: tuple[str, ...], series: Series) -> list[_Dim]:
    """Search ranges; clamps from what the log shows (a clamp well below the measured peak is
    impossible, one far above the largest setpoint is indistinguishable from none)."""
    v_meas = float(np.max(np.abs(series.speed)))
    v_cmd = float(np.max(np.abs(series.speed_cmd)))
    w_meas = float(np.max(np.abs(series.yaw_rate)))
    w_cmd = float(np.max(np.abs(series.yaw_rate_cmd)))
    ranges = {
        "yaw_delay": (0.0, 0.4, False), "speed_delay": (0.0, 0.5, False),
        "w_c_yaw": (0.3, 60.0, True), "w_c": (0.2, 50.0, True),
        "max_yaw_rate": (max(0.7 * w_meas, 0.05), max(1.5 * w_cmd, 1.2 * w_meas, 0.1), True),
        "max_speed": (max(0.7 * v_meas, 0.05), max(1.5 * v_cmd, 1.2 * v_meas, 0.1), True),
        "max_yaw_accel": (0.1, 50.0, True), "max_yaw_decel": (0.1, 50.0, True),
        "max_accel": (0.05, 20.0, True), "max_decel": (0.05, 20.0, True),
        COUPLING: (0.0, 1.0, False), TURN_COUPLING: (0.0, 1.0, False),
        TURN_RADIUS: (0.05, 20.0, True),
        OVERSHOOT: (0.0, 1.0, False), "speed_overshoot_s": (0.2, 10.0, True),
        YAW_OVERSHOOT: (-0.9, 2.0, False), "yaw_overshoot_s": (0.1, 10.0, True),
    }
    return [_Dim(name, *ranges[name]) for name in fields]


class _Channel:
    """One channel's objective: RMS of simulated minus measured output for a batch of sets.

    Runs only that channel (:mod:`companion.ident.channels`, respond's model step for step);
    the speed channel sees the turn rate of the turn-rate model in ``base``."""

    def __init__(self, series: Series, base: RoverParams, which: int, speed_scale: float):
        self.series, self.base, self.which = series, base, which
        self.speed_scale = speed_scale      # the top speed the turn-rate coupling is a share of
        self.measured = series.yaw_rate if which == 1 else series.speed
        self.evaluations = 0
        self._omega: dict[float, np.ndarray] = {}
        self._speed: dict[float, np.ndarray] = {}

    def _speed_grid(self, dt: float) -> np.ndarray:
        """The measured speed on the grid (linear between samples): what the turn-rate
        coupling reads in place of a speed model not yet fitted."""
        if dt not in self._speed:
            s = self.series
            g = channels.Grid.of(s.t, dt)
            self._speed[dt] = np.interp(s.t[0] + dt * np.arange(g.steps), s.t, s.speed)
        return self._speed[dt]

    def _turn_rate(self, p: RoverParams, n: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
        s = self.series
        return channels.turn_rate(s.t, s.yaw_rate_cmd, n, dt, float(s.yaw_rate[0]),
                                  p.yaw_delay, p.yaw_bandwidth, p.max_yaw_rate,
                                  p.max_yaw_accel, p.yaw_decel, p.speed_turn_coupling,
                                  self._speed_grid(dt), self.speed_scale, p.min_turn_radius,
                                  p.max_lat_accel, p.yaw_overshoot, p.yaw_overshoot_s)

    def _omega_grid(self, dt: float) -> np.ndarray:
        if dt not in self._omega:
            self._omega[dt] = self._turn_rate(self.base, 1, dt)[1][:, 0]
        return self._omega[dt]

    def cost(self, values: dict[str, np.ndarray], n: int, dt: float,
             per_log: bool = False) -> np.ndarray:
        """RMS of each of the ``n`` parameter sets over the series: shape (n,); with
        ``per_log``, over each joined log apart: shape (logs, n)."""
        s = self.series
        p = self.base.with_(**values)
        if self.which == 1:
            out, _ = self._turn_rate(p, n, dt)
        else:
            out = channels.speed(s.t, s.speed_cmd, self._omega_grid(dt), n, dt,
                                 float(s.speed[0]), p.speed_delay, p.w_c, p.max_speed,
                                 p.max_accel, p.decel, p.turn_speed_coupling, p.max_yaw_rate,
                                 p.speed_overshoot, p.speed_overshoot_s)
        self.evaluations += n
        err = out - self.measured[:, None]
        if per_log:
            return np.array([np.sqrt(np.mean(err[k] ** 2, axis=0)) for k in s.segments])
        return np.sqrt(np.mean(err * err, axis=0))


def _next_population(u: np.ndarray, cost: np.ndarray, population: int, width: float,
                     rng: np.random.Generator) -> np.ndarray:
    """One chain's next round: its best, then samples around the best and around the elite's
    mean with the elite's covariance (capped by ``width``)."""
    d = u.shape[1]
    order = np.argsort(cost)
    best = u[order[0]]
    elite = u[order[:max(2 * d + 2, len(u) // 10)]]
    # The elite's covariance is the valley's shape: sampling with it follows parameters that
    # trade against each other (a top speed and the coupling that lowers it), which independent
    # widths would cross only by luck.
    cov = np.atleast_2d(np.cov(elite.T)) + (0.05 * width) ** 2 * np.eye(d)
    top = float(np.sqrt(np.max(np.linalg.eigvalsh(cov))))
    chol = np.linalg.cholesky(cov) * min(1.0, width / top)
    half = population // 2
    around_best = best + rng.standard_normal((half, d)) @ chol.T
    around_elite = elite.mean(axis=0) + rng.standard_normal((population - half - 1, d)) @ chol.T
    # The best so far is re-evaluated on this round's grid, so costs stay comparable.
    return np.clip(np.vstack([best[None, :], around_best, around_elite]), 0.0, 1.0)


def _search(channel: _Channel, dims: list[_Dim], u0: np.ndarray, cfg: Search,
            rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """The cross-entropy search of the module docstring, ``cfg.chains`` independent chains
    evaluated together (one ``respond``-sized call per round for all of them: a delay traded
    against a lag has two valleys, and one chain may settle in the wrong one); the best unit
    vector found and its RMS."""
    d, chains = len(dims), cfg.chains

    def evaluate(u: np.ndarray, dt: float) -> np.ndarray:
        values = {dim.name: dim.value(u[:, i]) for i, dim in enumerate(dims)}
        return channel.cost(values, len(u), dt)

    (first, dt), *rounds = cfg.schedule
    u = rng.random((first * chains, d))
    u[0] = u0
    us, costs = np.split(u, chains), np.split(evaluate(u, dt), chains)
    for r, (population, dt) in enumerate(rounds):
        width = max(0.3 * cfg.shrink ** r, 0.003)
        us = [_next_population(uc, cc, population, width, rng) for uc, cc in zip(us, costs, strict=True)]
        costs = np.split(evaluate(np.vstack(us), dt), chains)
    best_chain = int(np.argmin([c.min() for c in costs]))
    k = int(np.argmin(costs[best_chain]))
    best, cost = us[best_chain][k], float(costs[best_chain][k])
    for r in range(cfg.polish):
        best, cost, moved = _polish_round(best, cost, evaluate, 0.1 * 0.6 ** r, cfg.schedule[-1][1])
        if not moved and r > 2:
            break
    return best, cost


def _polish_round(best: np.ndarray, cost: float, evaluate, width: float, dt: float,
                  ) -> tuple[np.ndarray, float, bool]:
    """One round of coordinate polishing: every parameter alone moved to 8 points within
    ``width`` (unit box) of the best, all in one batch; each parameter's best move that helps is
    taken together with the others' when that helps more (else the single best move alone).
    What the cross-entropy search leaves one clamp or one lag off by a little (clamps make the
    valley's floor a staircase)."""
    d = len(best)
    offsets = width * np.array([-1.0, -0.5, -0.25, -0.1, 0.1, 0.25, 0.5, 1.0])
    rows = np.repeat(best[None, :], d * len(offsets) + 1, axis=0)
    for i in range(d):
        rows[1 + i * len(offsets): 1 + (i + 1) * len(offsets), i] += offsets
    rows = np.clip(rows, 0.0, 1.0)
    costs = evaluate(rows, dt)
    base = float(costs[0])
    per_dim = costs[1:].reshape(d, len(offsets))
    step = np.zeros(d)
    for i in range(d):
        j = int(np.argmin(per_dim[i]))
        if per_dim[i, j] < base:
            step[i] = rows[1 + i * len(offsets) + j, i] - best[i]
    if not np.any(step):
        return best, min(cost, base), False
    single = rows[1 + int(np.argmin(per_dim))]
    joint = np.clip(best + step, 0.0, 1.0)
    both = evaluate(np.vstack([joint, single]), dt)
    k = int(np.argmin(both))
    return (joint, single)[k], float(both[k]), True


def _settle(channel: _Channel, dims: list[_Dim], best: dict[str, float], prior: RoverParams,
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
            out[name] = _prior_value(prior, name, out)
        return out

    # All of them at their priors at once; else one at a time, in field order (an accel limit
    # before its decel limit, whose prior may be "as accel").
    joint = moved(best, loose)
    if within([joint])[0]:
        return joint, {**status, **{name: PRIOR for name in loose}}
    values = dict(best)
    for name in loose:
        target = _prior_value(prior, name, values)
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


# The scan around each fitted value (:func:`_determined`): up to x2 and /2 for lags and limits,
# +-0.1 s for delays, +-0.3 for the couplings, in this many steps each way (quadratically
# spaced: the first 1 % of the span).
SCAN_STEPS = 10


def _scan(dim: _Dim, value: float) -> np.ndarray:
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


def _determined(channel: _Channel, dims: list[_Dim], values: dict[str, float],
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


def _prior_value(prior: RoverParams, name: str, values: dict[str, float]) -> float:
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
    channel = _Channel(series, base, which, _speed_scale(series, prior))
    commands = series.yaw_rate_cmd if which == 1 else series.speed_cmd
    start: dict[str, float] = {}
    for name in fields + extra:
        start[name] = _prior_value(prior, name, start)
    if float(np.max(np.abs(commands))) < MIN_COMMAND:
        # Never driven: nothing in the log speaks to this channel.
        return start, {name: PRIOR for name in fields + extra}, 0, {}
    dims = _dims(fields, series)
    u0 = np.array([dim.unit(start[dim.name]) for dim in dims])
    u_best, cost = _search(channel, dims, u0, cfg, rng)
    best = {dim.name: float(dim.value(u_best[i])) for i, dim in enumerate(dims)}
    if extra:
        wide = _dims(fields + extra, series)
        # (a whole search starts from the priors: the first's best sits in the valley the
        # extras' effect was imitated in, a slow lag for a late tail, and holds a chain there)
        u1 = np.array([dim.unit((start if wide_extra else {**start, **best})[dim.name])
                       for dim in wide])
        u_more, more = _search(channel, wide, u1,
                               replace(cfg, schedule=WIDE_SCHEDULE, shrink=WIDE_SHRINK,
                                       polish=WIDE_POLISH) if wide_extra
                               else replace(cfg, schedule=EXTRA_SCHEDULE), rng)
        if more < cost * (1.0 - cfg.tol):
            best = {dim.name: float(dim.value(u_more[i])) for i, dim in enumerate(wide)}
        else:
            best.update({name: start[name] for name in extra})
        dims = wide
    values, status = _settle(channel, dims, best, prior, cfg)
    still = [dim for dim in dims if status[dim.name] == FITTED]
    if still and len(still) < len(dims):
        # What moved to its prior changes what the rest are seen to do (a coupling that bit
        # only under a low clamp the search had found): look at those once more.
        values, again = _settle(channel, still, values, prior, cfg)
        status.update(again)
    determined = _determined(channel, dims, values, status, cfg)
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
    channel as fitted (the grid's best; determinacy as in :func:`_settle`: a factor of 1.4 or
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


def fit(series: Series, prior: RoverParams, search: Search = Search(),
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
    car = not series.vector and float(np.max(prior.min_turn_radius)) > 0
    if car:
        # A car driven by turn-rate setpoints (ArduPilot's Ackermann rover): its turning radius
        # clamps the turn rate by the measured speed, so the turn-rate channel fits it.
        yaw_fields = yaw_fields + (TURN_RADIUS,)
    # The rate loop's two time scales (a feed-forward that over- or under-drives the steering,
    # the integrator doing the rest): searched after the usual fields, for turn-rate setpoints
    # only (PX4's course loop is fitted on its own grid), and not for a car: at full lock its
    # turn rate is the steering's |v| / R whatever the rate loop asks, while the model's share
    # acts past the clamp, so the two trade against each other (SITL rover, 2026-12-02: share
    # -0.11 with a 0.81 m radius where SITL's is 0.9 m, the live identify test's bound).
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
