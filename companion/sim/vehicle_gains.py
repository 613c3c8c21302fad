"""Gains that belong to a vehicle file: tuned for it, recorded with it, found beside it.

``companion tune --vehicle V.toml`` writes a gains file that names the vehicle file and the
SHA-256 of its bytes; ``companion run --vehicle V.toml`` looks in V's folder for a gains file
tuned for exactly those bytes at the loop rate it flies, and when there is none tunes one on the
spot (:func:`companion.sim.robust.search.tune`) and stores it there for next time. A vehicle file that
changes (re-identified) no longer matches its old gains, so they are never applied by mistake.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..core.limits import DEFAULT_LIMITS, Limits
from ..core.trajectory import Trajectory
from ..errors import UserError
from . import gains as gains_mod
from . import vehicle_file
from .gains import TunedGains
from .plant import RoverParams
from .robust.config import RobustConfig, Spread
from .robust.search import RobustResult, tune


class NothingRobust(UserError):
    """The robust tuner found no gain set that held on every neighbour (exit 2)."""


def digest(vehicle_path: str | Path) -> str:
    try:
        return hashlib.sha256(Path(vehicle_path).read_bytes()).hexdigest()
    except OSError as exc:
        raise UserError(f"{vehicle_path}: cannot read: {exc}") from None


def vehicle_limits(vehicle: RoverParams, max_speed: float | None = None,
                   max_yaw_rate: float | None = None) -> Limits:
    """The companion's setpoint limits for a vehicle: what it can do (or the flags, if lower)."""
    def pick(flag: float | None, own: float, ceiling: float) -> float:
        own = own if math.isfinite(own) else ceiling    # none known: the companion's ceiling
        return min(flag, own) if flag is not None else own
    # a car driven by turn-rate setpoints: no command tighter than its turning radius (PX4's
    # velocity vectors leave that to PX4's own course loop)
    radius = float(vehicle.min_turn_radius) if vehicle.steered_by_radius else 0.0
    return Limits(max_speed=pick(max_speed, float(vehicle.max_speed), DEFAULT_LIMITS.max_speed),
                  max_yaw_rate=pick(max_yaw_rate, float(vehicle.max_yaw_rate),
                                    DEFAULT_LIMITS.max_yaw_rate),
                  min_turn_radius=radius)


def config_for(vehicle_path: str | Path, rate: float,
               references: Sequence[tuple[str, Trajectory]] = (), duration: float = 60.0,
               **search: Any) -> RobustConfig:
    """The robust tuner's configuration for a vehicle file at a loop rate (ArduPilot's 50 Hz
    scheduler ticks below 50 Hz), on the references given or the paper's ellipses.

    ``search``: RobustConfig's fields, a ``spread`` as a Spread or a mapping of its fields. What
    the vehicle's autopilot and steering kind add (companion.profiles.tune_settings) comes in
    here too, from the command that knows the profiles (companion.commands.flight.tune_search):
    this layer does not."""
    vehicle = vehicle_file.load(vehicle_path).params
    if isinstance(search.get("spread"), Mapping):
        search["spread"] = Spread(**search["spread"])
    return RobustConfig(vehicle=vehicle, rate_hz=rate, tick=0.02 if rate < 50 else None,
                        references=tuple(references), duration=duration,
                        limits=vehicle_limits(vehicle), **search)


def record(result: RobustResult, cfg: RobustConfig, vehicle_path: str | Path,
           command: str) -> TunedGains:
    """The tuned gains with their record: vehicle file, its hash, the ensemble, the command."""
    sha = digest(vehicle_path)
    weighed = [label if w == 1.0 else f"{label} (weight {w:g})"
               for label, w in zip(result.references, cfg.reference_weights(), strict=True)]
    lines = [f"robust tune for the vehicle file {vehicle_path} (sha256 {sha[:16]}...)",
             f"command: {command}",
             f"references: {', '.join(weighed)}; {cfg.duration:g} s each; telemetry "
             f"{cfg.rate_hz:g} Hz" + (f" on {cfg.tick * 1000:g} ms ticks" if cfg.tick else ""),
             f"ensemble: the vehicle and {len(result.vehicles) - 1} neighbours (lags x1+-"
             f"{cfg.spread.lag:g}, rate limits x1+-{cfg.spread.limit:g}, delays +"
             f"{cfg.spread.delay_samples:g} samples, coupling +-{cfg.spread.coupling:g}"
             + (f", speed up to x{1 + cfg.spread.over_drive:g} the command"
                if cfg.spread.over_drive > 0 else "") + f"), seed {cfg.seed}",
             "steady RMS (m) on the vehicle / worst neighbour: " + ", ".join(
                 f"{a:.3f}/{b:.3f}" for a, b in zip(result.nominal_steady_rms,
                                                    result.worst_steady_rms, strict=True))]
    return replace(result.gains, header="\n".join(lines), vehicle_file=Path(vehicle_path).name,
                   vehicle_sha256=sha)


def find_beside(vehicle_path: str | Path, rate: float) -> TunedGains | None:
    """A gains file in the vehicle file's folder tuned for these very bytes at this rate."""
    sha, folder = digest(vehicle_path), Path(vehicle_path).resolve().parent
    for path in sorted(folder.glob("*.toml")):
        if path.resolve() == Path(vehicle_path).resolve():
            continue
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError):
            continue
        if sha not in text:                 # cheap filter before parsing
            continue
        try:
            g = gains_mod.load(path)
        except UserError:
            continue
        if g.vehicle_sha256 == sha and math.isclose(g.rate_hz, rate, rel_tol=1e-9):
            return g
    return None


def path_beside(vehicle_path: str | Path, rate: float) -> Path:
    """Where gains tuned on the spot are kept: ``gains.toml`` beside ``vehicle.toml`` (what
    ``companion calibrate`` writes), else ``<stem>.gains-<rate>hz.toml``."""
    vehicle_path = Path(vehicle_path)
    plain = vehicle_path.with_name("gains.toml")
    if vehicle_path.name == "vehicle.toml" and not plain.exists():
        return plain
    return vehicle_path.with_name(f"{vehicle_path.stem}.gains-{rate:g}hz.toml")


def gains_for(vehicle_path: str | Path, rate: float, command: str,
              progress: Callable[[float], None] | None = None,
              log: Callable[[str], None] = lambda text: None, pool: Any = None,
              **search: Any) -> TunedGains:
    """The vehicle's gains at ``rate``: found beside it, else tuned now (``search``: the
    tuner's population, rounds, ...; ``pool``: robust.pool.worker_pool's) and stored there."""
    found = find_beside(vehicle_path, rate)
    if found is not None:
        log(f"gains tuned for {vehicle_path}: {found.source}")
        return found
    log(f"no gains tuned for {vehicle_path} at {rate:g} Hz yet: tuning them now (about a minute)")
    cfg = config_for(vehicle_path, rate, **search)
    try:
        result = tune(cfg, progress, pool)
    except RuntimeError as exc:
        raise NothingRobust(f"{vehicle_path}: {exc}") from None
    tuned = record(result, cfg, vehicle_path, command)
    out = path_beside(vehicle_path, rate)
    try:
        tuned.save(out)
    except OSError as exc:
        log(f"could not store the gains beside the vehicle ({out}: {exc}); using them anyway")
        return replace(tuned, source=f"tuned now for {vehicle_path}")
    log(f"gains tuned for {vehicle_path} stored in {out}")
    return replace(tuned, source=str(out))
