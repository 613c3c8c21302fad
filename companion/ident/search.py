"""The parameter space of a channel and the search over it.

Per channel, every parameter is mapped onto [0, 1] (log scale for lags and limits,
linear for delays and the coupling share); a uniform random population plus the prior, then
rounds that sample around the best so far and around the elite's mean with the elite's
covariance, capped by a width that shrinks each round (a cross-entropy search with full
covariance, so parameters that trade against each other are followed along their valley), three
independent chains side by side (a delay traded against a lag can have two valleys). One round
is one vectorised simulation of all chains' populations; the rounds on a 20 ms grid (ArduPilot's
50 Hz loop; on 40 ms the grid's own error is above the noise), the last on 10 ms. The
objective is the RMS of simulated minus measured output over the log.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .objective import Objective
from .series import Series

LIMITS = {"max_speed", "max_accel", "max_decel", "max_yaw_rate", "max_yaw_accel", "max_yaw_decel"}
LAGS = {"w_c", "w_c_yaw"}
DELAYS = {"speed_delay", "yaw_delay"}
COUPLING = "turn_speed_coupling"
TURN_COUPLING = "speed_turn_coupling"
COUPLINGS = {COUPLING, TURN_COUPLING}
OVERSHOOT = "speed_overshoot"     # a share, stepped as the couplings are
YAW_OVERSHOOT = "yaw_overshoot"   # a signed share (the rate loop's two time scales)
TURN_RADIUS = "min_turn_radius"   # a car's (speed / turn-rate setpoints): fitted in its channel


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
class Dim:
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


def search_space(fields: tuple[str, ...], series: Series) -> list[Dim]:
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
    return [Dim(name, *ranges[name]) for name in fields]


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


def minimise(channel: Objective, dims: list[Dim], u0: np.ndarray, cfg: Search,
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
