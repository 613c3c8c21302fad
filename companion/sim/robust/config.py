"""What a robust tune is for: the vehicle, its neighbours' spread, the references, the search's
size and the law's settings every candidate shares."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...core.limits import Limits
from ...core.trajectory import Ellipse, Trajectory
from ..plant import RoverParams
from .references import PAPER_F_R, ellipse_path_accel, ellipse_speed, ellipse_turn_rate

TURN_ROOM = 0.8              # a reference's peak turn rate at most this share of the vehicle's


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
    # (256 x 6: a smaller search left SITL's tracking measurably worse, for its time see
    # docs/design/robust-tuning.md)
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
    # a candidate whose turn-rate setpoints sit at their limit is a limit cycle, rejected (False:
    # the vehicle's autopilot ignores the turn-rate setpoint, its profile says: PX4's u_p)
    limit_cycles: bool = True
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
        limit-cycle rule rejects, so only gains too slow to follow anything survive. An
        acceleration beyond the limit leaves the vehicle a metre or more behind whatever the
        gains (the 0.12 Hz ellipse asks 1.80 m/s^2, ArduPilot's rovers have about 1.0); for a car
        its log RMS in the objective bought small relative gains there with the 0.08 Hz
        tracking, so a car's tune leaves it out (``accel_room`` 1: profiles.ackermann). A
        skid-steer rover's does not need to (it tracks the same with and without), and PX4's
        deceleration is too loosely identified to judge by. With ``speed_room``, those whose
        peak speed exceeds that share of the vehicle's top speed are left out too: a rover
        flies them a metre or more off whatever the gains, and they cost tuning time. The
        measurements behind each: docs/design/robust-tuning.md."""
        if self.references:
            return self.references
        return tuple((f"ellipse {f:g} Hz", Ellipse.paper(f)) for f in self._paper_kept())

    def reference_weights(self) -> np.ndarray:
        """Each reference's weight in the objective, in :meth:`reference_list`'s order:
        ``reach_weight`` for a paper ellipse the vehicle cannot follow (its peak acceleration
        along the path beyond the slower of the vehicle's speed limits), 1 for the rest and for
        references given. Not its speed: a rover whose top speed is a little below a
        reference's peak still follows it closely.

        Such a reference leaves an error no gains take away, and in the objective the gains
        that shave some of it cost the references the vehicle can follow (measured:
        docs/design/robust-tuning.md)."""
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
