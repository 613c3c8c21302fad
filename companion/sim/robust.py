"""Robust tuning: gains that hold on an identified vehicle and on its plausible neighbours.

:mod:`companion.sim.tuning` finds the best gains for one linear model; on a real autopilot (rate
limits, delay, coupling) gains that exploit that model's exact form meet the limits as a relay
and limit-cycle. Here every candidate gain set is simulated, in one batch, on

* an **ensemble**: the identified vehicle (:mod:`companion.sim.vehicle_file`) and neighbours with
  each identified parameter perturbed (lags and rate limits by tens of percent, delays by one or
  two telemetry samples, the skid-steer coupling), deterministic for a seed;
* the **telemetry as the autopilot delivers it**: samples on the scheduler's ticks (ArduPilot's
  20 / 20 / 20 / 40 ms at 40 Hz) with EKF-like noise;
* **references**: the missions given, else the paper's ellipse at 0.04, 0.08 and 0.12 Hz plus a
  slower one (0.02 Hz), so gains that suit a fast reference cannot orbit a slow one.

The objective rewards steady tracking on every reference (log of the ensemble-mean steady RMS,
so a 5 cm and a 50 cm reference count alike, plus a smaller share of f_cost for the approach)
and penalises command chatter (total variation of the setpoints per second). A candidate whose
**worst** neighbour limit-cycles (yaw-rate setpoint at its limit more than 5 % of the second
half) or diverges on any reference is rejected outright.

The search is :mod:`companion.sim.tuning`'s (seeded random search, then rounds of perturbation
around the elite) over the same gain space, with the actuator lead left out: a lead's gain is
what turns a rate limit into a relay. On top of it, this search chooses the law's extensions for
rate-limited, delayed inner loops (:mod:`companion.core.pzc`): a separate preview time for the
turning part of the acceleration feed-forward (``accel_ff_turn``) and braking-curve P terms with
integrator hold (``brake_accel``, ``brake_yaw_accel``), each behind a flag, the braking
accelerations as factors of the identified vehicle's decelerations (:data:`EXTRA_RANGES`), and
on a late speed loop (``predict_min_delay``, the autopilot profile's) the speed's delay
prediction (``predict_s``, a share of the identified delay: :data:`PREDICT_RANGE`); on a speed
loop identified to overshoot (``cancel_min_overshoot``, the profile's) every candidate sends
its speed through that overshoot's inverse (:meth:`RobustConfig.overshoot_cancel`). The
seeds include the speed channel's delay + lag as the speed preview, so the search starts where
the physics says the preview belongs.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import math
import multiprocessing
import signal
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..core.filter import FilterGains
from ..core.limits import Limits
from ..core.pzc import PZCGains, PZCTracker, reference_heading_rate
from ..core.signals import Num, Reference
from ..core.trajectory import Ellipse, Trajectory
from .batch import SimConfig, simulate
from .gains import TunedGains
from .plant import RoverParams, RoverState
from .plant_lanes import batch_model
from .tuning import Candidates, perturb, random_candidates

PAPER_F_R = (0.02, 0.04, 0.08, 0.12)
LIMIT_CYCLE_SHARE = 0.05     # yaw-rate setpoint at its limit in more of the second half: rejected
TURN_ROOM = 0.8              # a reference's peak turn rate at most this share of the vehicle's

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
# half of it: on SITL's car (0.47 s) the whole delay tracked the 0.08 Hz ellipse best and the
# slow ones worst (model: 0.03 / 0.09 m at 0.04 / 0.08 Hz, 0.04 m at 0.02 Hz; flown 0.036 /
# 0.109), half of it 0.019 / 0.112 m and 0.009 m at 0.02 Hz (2026-12-05).
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


@dataclass(frozen=True)
class Spread:
    """How far the neighbours stray from the identified vehicle."""

    lag: float = 0.3          # lags x (1 +- lag)
    limit: float = 0.15       # rate limits x (1 +- limit)
    delay_samples: float = 1  # delays + up to this many telemetry samples (never below 0)
    coupling: float = 0.15    # coupling +- this (clipped to [0, 1])
    # A speed loop without integral action settles where its feed-forward puts it, not at the
    # command: neighbours whose speed is up to (1 + over_drive) x the command and stays there
    # (speed_overshoot at that share, never taken back). 0: none (a speed loop that closes).
    over_drive: float = 0.0


@dataclass(frozen=True)
class RobustConfig:
    vehicle: RoverParams
    rate_hz: float = 40.0
    tick: float | None = 0.02          # s, autopilot scheduler tick (ArduPilot: 1 / 50 Hz)
    references: tuple[tuple[str, Trajectory], ...] = ()   # (label, trajectory); () = paper's
    duration: float = 60.0
    limits: Limits = Limits()
    neighbours: int = 6                # besides the identified vehicle itself
    spread: Spread = Spread()
    noise_pos: float = 0.005           # m, EKF-like white noise on the position samples
    noise_yaw: float = 0.002           # rad
    # (256 x 6, about 80 s on two busy cores: on ArduPilot SITL the same identified vehicle
    # tuned at 160 x 5 tracked the 0.08 Hz ellipse to 0.094-0.100 m, at 256 x 6 to 0.065 m)
    population: int = 256
    rounds: int = 6
    elite: int = 12
    chatter_weight: float = 0.05       # objective per (m/s + rad/s) per s of setpoint variation
    # m added to each reference's steady RMS before its log: differences well below it count
    # for little (a reference held to a few mm does not outweigh centimetres on a faster one)
    rms_floor: float = 0.005
    plant_dt: float = 0.02             # s: one exact step per ArduPilot tick (within 3 % of 1 ms)
    seed: int = 1
    min_progress: float = 0.0          # the law's progress floor for every candidate (PX4, a car)
    speed_law: str = "projected"       # every candidate's (a car: "paper", it turns only moving)
    course_tau: float = 0.0            # s, every candidate's course correction (core.course)
    # every candidate's integration zone past the braking curve's knee, in knees (core.pzc;
    # 1: the integrators hold at the knee; PX4's over-driving speed loop: more)
    brake_integrate: float = 1.0
    approach_cone: float = 0.0         # rad, every candidate's approach cone (core.pzc; 0: none)
    # s: on a vehicle whose identified speed delay is at least this, the search chooses whether
    # and how far ahead each candidate predicts its speed (core.predict, PZCGains.predict_s:
    # PREDICT_RANGE); None: none does (the autopilot's profile says)
    predict_min_delay: float | None = None
    # on a vehicle whose identified speed overshoot share is at least this, every candidate
    # sends its speed through the overshoot's inverse (core.overshoot); None: none does
    cancel_min_overshoot: float | None = None
    # None: the references are not checked against the vehicle's acceleration; a number: those
    # whose peak acceleration along the path exceeds that share of it are left out (a car's)
    accel_room: float | None = None
    # None: not checked against the vehicle's top speed; a number: references whose peak speed
    # exceeds that share of it are left out (PX4 SIH's rover, 2.5-3 m/s, and the 0.12 Hz ellipse)
    speed_room: float | None = None
    # the weight in the objective of a reference this vehicle cannot follow (its peak
    # acceleration along the path beyond the slower of the vehicle's speed limits); 1: as much
    # as any other (reference_weights)
    reach_weight: float = 1.0
    # processes that simulate each round's candidates (this one and workers - 1 spawned): the
    # same gains at any count (:func:`evaluate`), in less wall time where cores are free
    workers: int = 1

    def law_settings(self) -> dict[str, Any]:
        """The law's settings every candidate shares (PZCGains fields): the tuner flies each
        candidate with them and the tuned gains carry them."""
        return {"min_progress": self.min_progress, "speed_law": self.speed_law,
                "course_tau": self.course_tau, "brake_integrate": self.brake_integrate,
                "approach_cone": self.approach_cone, **self.overshoot_cancel()}

    def overshoot_cancel(self) -> dict[str, float]:
        """The law's overshoot cancellation for this vehicle (PZCGains.cancel_overshoot,
        cancel_overshoot_s): the identified overshoot where it reaches
        ``cancel_min_overshoot`` and is taken back (a finite time), else none ({})."""
        share = float(np.mean(self.vehicle.speed_overshoot))
        tau = float(np.mean(self.vehicle.speed_overshoot_s))
        if (self.cancel_min_overshoot is None or not share >= self.cancel_min_overshoot
                or not math.isfinite(tau)):
            return {}
        return {"cancel_overshoot": share, "cancel_overshoot_s": tau}

    @property
    def predict_delay(self) -> float:
        """The speed delay the candidates may predict a share of (PREDICT_RANGE): the
        identified one where it reaches ``predict_min_delay``, else 0 (none predicts)."""
        delay = float(np.max(self.vehicle.speed_delay))
        if self.predict_min_delay is None or not delay >= self.predict_min_delay:
            return 0.0
        return delay

    def reference_list(self) -> tuple[tuple[str, Trajectory], ...]:
        """The references given, else the paper's ellipses this vehicle can turn through with
        room to correct (their peak turn rate within TURN_ROOM of its limit) and, with
        ``accel_room``, accelerate along (their peak acceleration along the path within that
        share of the slower of its speed limits). The slowest is always kept.

        A turn rate at the limit holds every candidate that follows it there, which the
        limit-cycle rule rejects, so only gains too slow to follow anything survive (SITL
        rover-skid with ATC_STR_RAT_MAX 60 deg/s, 1.055 rad/s, 2026-12-02: with the 0.12 Hz
        ellipse, 1.51 rad/s, 1.15 m at 0.08 Hz; with the 0.08 Hz one, 1.005 rad/s, 1.80 m; tuned
        on 0.02 and 0.04 Hz alone the same vehicle file simulates 0.0038 / 0.083 m; Kanayama
        0.13 m). An acceleration beyond the limit leaves the vehicle a metre or more behind
        whatever the gains (the 0.12 Hz ellipse asks 1.80 m/s^2, ArduPilot's rovers have about
        1.0); for SITL's car its log RMS in the objective bought small relative gains there with
        the 0.08 Hz tracking (four robust tunes on all four ellipses: 0.174 / 0.266 / 0.341 m
        simulated at 0.08 Hz; four without 0.12 Hz: 0.162-0.186 m; 0.022-0.026 m at 0.04 Hz
        either way, 2026-12-03), so a car's tune leaves it out (``accel_room`` 1:
        profiles.ackermann). A skid-steer rover's does not need to (stock rover-skid 0.049 /
        0.052 m at 0.08 Hz with and without), and PX4's deceleration is too loosely identified to judge by (0.65 to
        3 m/s^2 over sessions of one SIH rover). With ``speed_room``, those whose peak speed
        exceeds that share of the vehicle's top speed are left out too: PX4 SIH's rover (3 m/s)
        flew the 0.12 Hz ellipse (4.77 m/s) to 1.4-1.9 m whatever the gains, and it cost a
        quarter of calibrate's final tune (2026-12-04)."""
        if self.references:
            return self.references
        return tuple((f"ellipse {f:g} Hz", Ellipse.paper(f)) for f in self._paper_kept())

    def reference_weights(self) -> np.ndarray:
        """Each reference's weight in the objective, in :meth:`reference_list`'s order:
        ``reach_weight`` for a paper ellipse the vehicle cannot follow (its peak acceleration
        along the path beyond the slower of the vehicle's speed limits), 1 for the rest and for
        references given. Not its speed: stock rover-skid (3.06-3.11 m/s) follows the 0.08 Hz
        ellipse (3.18 m/s at its peak) to 0.04 m.

        Such a reference leaves an error no gains take away, and in the objective the gains
        that shave some of it cost the references the vehicle can follow: on SITL rover-skid
        with ATC_ACCEL_MAX 0.5 (0.52 m/s^2 against the 0.08 Hz ellipse's 0.80) the tune
        counting it whole flew 0.017-0.018 m at 0.04 Hz, Kanayama 0.035 (2026-12-05)."""
        if self.references:
            return np.ones(len(self.references))
        return np.array([self.reach_weight if ellipse_path_accel(f) > self._slower_accel else 1.0
                         for f in self._paper_kept()])

    @property
    def _slower_accel(self) -> float:
        """m/s^2: the slower of the vehicle's speed limits (acceleration, deceleration)."""
        return float(np.min(np.minimum(self.vehicle.max_accel, self.vehicle.decel)))

    def _paper_kept(self) -> list[float]:
        """The paper's ellipses :meth:`reference_list` keeps (their f_r, Hz)."""
        top = TURN_ROOM * float(np.min(self.vehicle.max_yaw_rate))
        accel = math.inf if self.accel_room is None else self.accel_room * self._slower_accel
        fastest = (math.inf if self.speed_room is None
                   else self.speed_room * float(np.min(self.vehicle.max_speed)))
        return [f for f in PAPER_F_R if f == min(PAPER_F_R)
                or (ellipse_turn_rate(f) <= top and ellipse_path_accel(f) <= accel
                    and ellipse_speed(f) <= fastest)]


def _ellipse_samples(f_r: float, samples: int) -> list[Reference]:
    """One period of the paper's ellipse at ``f_r``, ``samples`` evenly spaced."""
    ellipse = Ellipse.paper(f_r)
    return [ellipse.sample(float(t)) for t in np.linspace(0.0, 1.0 / f_r, samples, endpoint=False)]


# The ellipse's peaks are remembered: every evaluation asks for the reference list again, and
# sampling them was 7 % of one (2026-12-05).
@functools.lru_cache(maxsize=64)
def ellipse_turn_rate(f_r: float, samples: int = 2000) -> float:
    """The paper's ellipse's peak turn rate at ``f_r`` (rad/s; 1.13 at 0.08 Hz)."""
    return max(abs(reference_heading_rate(r)) for r in _ellipse_samples(f_r, samples))


@functools.lru_cache(maxsize=64)
def ellipse_speed(f_r: float, samples: int = 2000) -> float:
    """The paper's ellipse's peak speed at ``f_r`` (m/s; 3.18 at 0.08 Hz, 4.77 at 0.12 Hz)."""
    return max(math.hypot(r.vx, r.vy) for r in _ellipse_samples(f_r, samples))


@functools.lru_cache(maxsize=64)
def ellipse_path_accel(f_r: float, samples: int = 2000) -> float:
    """The paper's ellipse's peak acceleration along its path at ``f_r`` (m/s^2: the rate of
    change of its speed, (v . a) / |v|; 0.80 at 0.08 Hz, growing with f_r squared)."""
    return max(abs(r.vx * r.ax + r.vy * r.ay) / math.hypot(r.vx, r.vy)
               for r in _ellipse_samples(f_r, samples))


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


def _stack_params(vehicles: Sequence[RoverParams], repeat: int, tile: int) -> RoverParams:
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


class StackedReference:
    """Several trajectories side by side: vehicle i follows ``trajs[which[i]]`` (one batch)."""

    def __init__(self, trajs: Sequence[Trajectory], which: np.ndarray):
        self.trajs, self.which = list(trajs), np.asarray(which)
        self.duration = None

    def sample(self, t: float) -> Reference:
        samples = [tr.sample(t) for tr in self.trajs]
        fields = ("x", "y", "vx", "vy", "ax", "ay")
        table = {f: np.array([float(getattr(s, f)) for s in samples]) for f in fields}
        return Reference(*(table[f][self.which] for f in fields))


def _reference(refs: Sequence[Trajectory], n_cand: int, n_veh: int) -> Trajectory:
    """Vehicle order: candidate-major, then vehicle, then reference."""
    which = np.tile(np.arange(len(refs)), n_cand * n_veh)
    ellipses = [r for r in refs if isinstance(r, Ellipse)]
    if len(ellipses) == len(refs) and all(
            r.duration is None and (r.ax, r.bx, r.ay, r.by, r.cx, r.cy) == (6.0, -1.0, 2.0, 3.0, 0.0, 0.0)
            for r in ellipses):
        return Ellipse.paper(np.array([float(r.f_r) for r in ellipses])[which])
    return StackedReference(refs, which)


@dataclass
class Evaluation:
    objective: np.ndarray              # per candidate (inf: rejected)
    steady_rms: np.ndarray             # [candidate, vehicle, reference]
    f_cost: np.ndarray
    yaw_at_limit: np.ndarray
    chatter: np.ndarray                # speed TV + yaw-rate TV, per s
    rejected: np.ndarray               # per candidate: why ("" if kept)


def _extension_values(cands: Candidates, scales: tuple[float, float],
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


def _tracker(cands: Candidates, repeat: int, limits: Limits,
             scales: tuple[float, float] = DEFAULT_BRAKE_SCALE,
             law: Mapping[str, Any] | None = None, predict_delay: float = 0.0) -> PZCTracker:
    """The candidates as one tracker of ``len(cands) * repeat`` vehicles, each candidate's
    gains ``repeat`` times, with the ``law`` settings they share (RobustConfig.law_settings)."""
    p, f = cands.params, cands.flags
    rep = lambda a: np.repeat(a, repeat)  # noqa: E731
    separate = f["separate_yaw"] > 0.5
    accel_ff = np.where(f["use_accel_ff"] > 0.5, p["accel_ff"], 0.0)
    ext = _extension_values(cands, scales, predict_delay)
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
    ext = {k: float(v[i]) for k, v in _extension_values(cands, scales, predict_delay).items()}
    return fg, replace(pg, accel_ff_turn=None if math.isnan(ext["accel_ff_turn"])
                       else ext["accel_ff_turn"],
                       brake_accel=ext["brake_accel"], brake_yaw_accel=ext["brake_yaw_accel"],
                       predict_s=ext["predict_s"])


def _simulate_part(cands: Candidates, cfg: RobustConfig, vehicles: Sequence[RoverParams],
                   first: int, total: int, progress: Callable[[float], None] | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Candidates ``first`` .. ``first + len(cands)`` of a batch of ``total``: steady RMS,
    f_cost, share at the yaw-rate limit and chatter, each [candidate, vehicle, reference]. Each
    part draws the whole batch's noise (SimConfig.noise_slice), so a batch split across
    processes gives what it gives in one."""
    refs = [tr for _, tr in cfg.reference_list()]
    n_c, n_v, n_r = len(cands), len(vehicles), len(refs)
    n = n_c * n_v * n_r
    params = _stack_params(vehicles, n_r, n_c)
    sim = SimConfig(duration=cfg.duration, control_rate=cfg.rate_hz, max_plant_dt=cfg.plant_dt,
                    tick=cfg.tick, noise_pos=cfg.noise_pos, noise_yaw=cfg.noise_yaw,
                    seed=cfg.seed, yaw_rate_limit=min(cfg.limits.max_yaw_rate,
                                                      float(np.min(params.max_yaw_rate))),
                    noise_slice=(total * n_v * n_r, first * n_v * n_r))
    with np.errstate(all="ignore"):
        result = simulate(_tracker(cands, n_v * n_r, cfg.limits, brake_scales(cfg.vehicle),
                                   cfg.law_settings(), cfg.predict_delay), params,
                          _reference(refs, n_c, n_v), n, sim, progress)
    shape = (n_c, n_v, n_r)
    return (np.asarray(result.steady_rms).reshape(shape),
            np.asarray(result.f_cost).reshape(shape),
            np.asarray(result.yaw_at_limit).reshape(shape),
            (np.asarray(result.speed_tv) + np.asarray(result.yaw_rate_tv)).reshape(shape))


# Below this many candidates a batch is not split (the step loop's overhead, about a third of
# a second per evaluation on this machine, would dominate each part).
MIN_SPLIT = 16


def evaluate(cands: Candidates, cfg: RobustConfig, vehicles: Sequence[RoverParams],
             progress: Callable[[float], None] | None = None,
             pool: Executor | None = None, workers: int = 1) -> Evaluation:
    """Every candidate on every vehicle and reference. With a ``pool`` of ``workers - 1``
    processes the candidates are split ``workers`` ways, this process flying the first part;
    the figures are the same as in one batch (:func:`_simulate_part`)."""
    n_c = len(cands)
    parts = 1 if pool is None else max(1, min(workers, n_c // MIN_SPLIT))
    bounds = [round(i * n_c / parts) for i in range(parts + 1)]
    assert pool is not None or parts == 1
    futures = [pool.submit(_simulate_part, cands.take(np.arange(a, b)), cfg, vehicles, a, n_c)
               for a, b in itertools.pairwise(bounds[1:])] if pool is not None else []
    own = _simulate_part(cands.take(np.arange(bounds[0], bounds[1])) if parts > 1 else cands,
                         cfg, vehicles, 0, n_c, progress)
    results = [own] + [f.result() for f in futures]
    rms, cost, at_limit, chatter = (np.concatenate([r[i] for r in results]) for i in range(4))
    finite = np.isfinite(rms) & np.isfinite(cost) & (rms < 1e3)
    rms_mean = np.where(finite, rms, np.inf).mean(axis=1)            # [cand, ref]
    cost_mean = np.where(finite, cost, np.inf).mean(axis=1)
    weights = cfg.reference_weights()               # sum / count: the mean where all are 1

    def weighted(per_ref: np.ndarray) -> np.ndarray:
        return (per_ref * weights).sum(axis=1) / weights.sum()

    objective = (weighted(np.log(rms_mean + cfg.rms_floor)) + 0.25 * weighted(np.log(cost_mean))
                 + cfg.chatter_weight * np.where(finite, chatter, np.inf).mean(axis=(1, 2)))
    rejected = np.full(n_c, "", dtype=object)
    cycling = (at_limit > LIMIT_CYCLE_SHARE).any(axis=(1, 2))
    if cfg.vehicle.velocity_vector:
        # PX4 is sent u_p and ignores the yaw-rate setpoint: its limit says nothing there
        cycling = np.zeros(n_c, dtype=bool)
    diverged = ~finite.all(axis=(1, 2))
    rejected[cycling] = "limit cycle"
    rejected[diverged] = "diverged"
    objective = np.where(cycling | diverged | ~np.isfinite(objective), np.inf, objective)
    return Evaluation(objective, rms, cost, at_limit, chatter, rejected)


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


def _random(rng: np.random.Generator, n: int, predict: bool = False) -> Candidates:
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


def _perturb(rng: np.random.Generator, parents: Candidates, n: int, sigma: float,
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


def _predict_seeds(start: Candidates) -> Candidates:
    """The seeds without the prediction, then the firmer ones (every extension on) again with
    it at PREDICT_SEED of the delay."""
    n = len(start)
    start.params["predict_k"] = np.full(n, PREDICT_SEED)
    start.flags["use_predict"] = np.zeros(n)
    firm = np.flatnonzero(start.flags["use_brake"] > 0.5)
    again = start.take(firm)
    again.flags["use_predict"] = np.ones(len(firm))
    return Candidates.concat([start, again])


@dataclass
class RobustResult:
    gains: TunedGains
    objective: float
    references: list[str]
    nominal_steady_rms: list[float]            # the identified vehicle, per reference
    worst_steady_rms: list[float]              # the worst neighbour, per reference
    nominal_f_cost: list[float]
    worst_yaw_at_limit: float
    vehicles: list[RoverParams]
    evaluated: int
    rejected: dict[str, int] = field(default_factory=dict)


def _worker_start() -> None:
    """Each spawned process first: Ctrl-C is the parent's to act on (it stops the search and
    shuts the pool down), not a traceback from every worker."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _warm() -> None:
    """A worker's first task when the pool is started ahead (:func:`worker_pool`): unpickling
    it imported this module, and one step loads the compiled plant (numba's cache)."""
    model = batch_model(RoverParams.stock_rover(), 2)
    model.step(RoverState(np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2)),
               0.0, 0.0, 0.02)


@contextlib.contextmanager
def _workers(count: int) -> Iterator[Executor | None]:
    """``count - 1`` spawned processes for :func:`evaluate` (None for one: this process
    alone). Spawned, not forked: the caller may have threads (a link, a progress bar)."""
    if count <= 1:
        yield None
        return
    with ProcessPoolExecutor(count - 1, mp_context=multiprocessing.get_context("spawn"),
                             initializer=_worker_start) as pool:
        yield pool


@contextlib.contextmanager
def worker_pool(count: int) -> Iterator[Executor | None]:
    """:func:`tune`'s processes started now and warmed (Python, numpy, this module and the
    compiled plant loaded: about 2-3 s each on a slow day) while the caller does other work, for
    ``tune(cfg, pool=...)`` with ``cfg.workers == count`` (calibrate: during its refining tune
    and flight). Idle, a worker only waits."""
    with _workers(count) as pool:
        if pool is not None:
            for _ in range(count - 1):
                pool.submit(_warm)
        yield pool


def _search(cfg: RobustConfig, vehicles: Sequence[RoverParams], population: Candidates,
            rng: np.random.Generator, rejected: dict[str, int], total: int,
            progress: Callable[[float], None] | None, pool: Executor | None
            ) -> tuple[Candidates, np.ndarray, int]:
    """The rounds of :func:`tune`: evaluate, keep the elite, perturb; (the elite, best first,
    their objectives, and how many candidates were evaluated)."""
    best: Candidates | None = None
    evaluated = 0
    best_obj = np.array([])
    for r in range(cfg.rounds):
        def round_progress(f: float, r: int = r) -> None:
            if progress is not None:
                progress((r + f) / total)
        ev = evaluate(population, cfg, vehicles, None if progress is None else round_progress,
                      pool, cfg.workers)
        evaluated += len(population)
        for why in rejected:
            rejected[why] += int(np.sum(ev.rejected == why))
        merged = population if best is None else Candidates.concat([best, population])
        merged_obj = ev.objective if best is None else np.concatenate([best_obj, ev.objective])
        order = np.argsort(merged_obj)[:cfg.elite]
        best, best_obj = merged.take(order), merged_obj[order]
        population = _perturb(rng, best, cfg.population, 0.5 * 0.6 ** r,
                              cfg.predict_delay > 0)
    assert best is not None   # cfg.rounds >= 1 (the command refuses fewer)
    return best, best_obj, evaluated


def _confirmed(best: Candidates, best_obj: np.ndarray, cfg: RobustConfig,
               vehicles: Sequence[RoverParams], progress: Callable[[float], None] | None
               ) -> tuple[Candidates, Evaluation]:
    """The best of the elite that holds again simulated on its own, and that evaluation.

    Each vehicle draws the noise of the whole batch it is simulated in, so a gain set at the
    edge of a limit cycle can hold in its round and not alone: on one calibration of the mixed
    matrix rover (2026-12-05) the winner's 0.12 Hz ellipse held on every neighbour in its round
    (worst 1.03 m) and limit-cycled on one alone (3.06 m), and calibrate stopped with nothing
    robust while the third of the elite held both times. The winner that holds alone is taken
    as before; only where it does not does the next one get its turn."""
    failed: tuple[Candidates, Evaluation] | None = None
    for i in np.flatnonzero(np.isfinite(best_obj)):
        winner = best.take(np.array([i]))
        ev = evaluate(winner, cfg, vehicles, progress)
        progress = None                      # the bar counts the first one's evaluation
        if math.isfinite(float(ev.objective[0])):
            return winner, ev
        failed = failed or (winner, ev)
    if failed is None:                       # nothing held in any round either
        winner = best.take(np.array([0]))
        failed = winner, evaluate(winner, cfg, vehicles, progress)
    return failed                            # not finite: tune() says nothing is robust


def tune(cfg: RobustConfig, progress: Callable[[float], None] | None = None,
         pool: Executor | None = None) -> RobustResult:
    """Search the gains for ``cfg.vehicle`` and its ensemble; ``progress(fraction)``. ``pool``:
    :func:`worker_pool`'s processes (``cfg.workers - 1`` of them), else spawned here."""
    rng = np.random.default_rng(cfg.seed)
    period = 1.0 / cfg.rate_hz
    vehicles = ensemble(cfg.vehicle, cfg.neighbours, cfg.spread, period, cfg.seed)
    predict = cfg.predict_delay > 0
    start = _predict_seeds(seeds(cfg.vehicle)) if predict else seeds(cfg.vehicle)
    population = Candidates.concat([start, _random(rng, max(1, cfg.population - len(start)),
                                                   predict)])
    rejected = {"limit cycle": 0, "diverged": 0}
    total = cfg.rounds + 1
    with (contextlib.nullcontext(pool) if pool is not None else _workers(cfg.workers)) as pool:
        best, best_obj, evaluated = _search(cfg, vehicles, population, rng, rejected, total,
                                            progress, pool)
    winner, ev = _confirmed(best, best_obj, cfg, vehicles, None if progress is None else (
        lambda f: progress((cfg.rounds + f) / total)))
    fg, pg = candidate_gains(winner, 0, brake_scales(cfg.vehicle), cfg.predict_delay)
    pg = replace(pg, **cfg.law_settings())
    labels = [label for label, _ in cfg.reference_list()]
    if not math.isfinite(float(ev.objective[0])):
        raise RuntimeError("no gain set held on every neighbour: widen the search "
                           "(--population, --rounds) or check the vehicle file")
    return RobustResult(
        TunedGains(fg, pg, rate_hz=cfg.rate_hz, w_c=float(np.mean(cfg.vehicle.w_c)),
                   d_cen=float(np.mean(cfg.vehicle.d_cen)), cost=float(ev.objective[0])),
        objective=float(ev.objective[0]), references=labels,
        nominal_steady_rms=[float(v) for v in ev.steady_rms[0, 0]],
        worst_steady_rms=[float(v) for v in ev.steady_rms[0].max(axis=0)],
        nominal_f_cost=[float(v) for v in ev.f_cost[0, 0]],
        worst_yaw_at_limit=float(ev.yaw_at_limit[0].max()), vehicles=vehicles,
        evaluated=evaluated, rejected=rejected)
