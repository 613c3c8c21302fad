"""Gains tuned for a vehicle file: the robust tuner's configuration for it, the search
settings the commands use, and the record a gains file keeps of what it was tuned for.

``companion tune --vehicle V.toml`` writes a gains file that names the vehicle file and the
SHA-256 of its bytes; ``companion run --vehicle V.toml`` flies a gains file found beside V
tuned for exactly those bytes at its loop rate, and when there is none tunes one on the spot
(:func:`companion.sim.robust.search.tune`) and stores it there for next time
(:mod:`companion.app.vehicle` reads and writes the files). A vehicle file that changes
(re-identified) no longer matches its old gains, so they are never applied by mistake.

No file is read here: the vehicle comes in as its model and limits, already loaded.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.limits import Limits
from ..core.trajectory import Trajectory
from ..errors import UserError
from .gains import TunedGains
from .plant import RoverParams
from .robust.config import RobustConfig, Spread

if TYPE_CHECKING:                   # the search itself is imported only to tune
    from .robust.search import RobustResult

# The refining flight's gains in ``companion calibrate``: a quick robust search, enough to fly
# 30 s of the 0.08 Hz ellipse without a limit cycle (the tuner rejects those on every
# neighbour); the gains kept are tuned once, at the end, on the model kept.
REFINE_SEARCH = {"population": 32, "rounds": 1}
# ``calibrate``'s final search: 128 x 4 instead of the tuner's 256 x 6, close to it in
# simulation at a fraction of the time (docs/calibrate-and-identify.md gives the figures).
FINAL_SEARCH = {"population": 128, "rounds": 4}
MAX_WORKERS = 4             # processes for a final search: at most this many, one per core


class NothingRobust(UserError):
    """The robust tuner found no gain set that held on every neighbour (exit 2)."""


def tune_workers() -> int:
    """A final search's processes: one per core this process may use, up to MAX_WORKERS (the
    gains do not depend on it)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:        # not Linux
        cores = os.cpu_count() or 1
    return max(1, min(MAX_WORKERS, cores))


def config_for(vehicle: RoverParams, limits: Limits, rate: float,
               references: Sequence[tuple[str, Trajectory]] = (), duration: float = 60.0,
               **search: Any) -> RobustConfig:
    """The robust tuner's configuration for a vehicle model with its ``limits`` at a loop rate
    (ArduPilot's 50 Hz scheduler ticks below 50 Hz), on the references given or the paper's
    ellipses.

    ``search``: RobustConfig's fields, a ``spread`` as a Spread or a mapping of its fields;
    what the vehicle's autopilot and steering kind add comes in here too
    (:attr:`companion.vehicle.Vehicle.tune_settings`)."""
    if isinstance(search.get("spread"), Mapping):
        search["spread"] = Spread(**search["spread"])
    return RobustConfig(vehicle=vehicle, rate_hz=rate, tick=0.02 if rate < 50 else None,
                        references=tuple(references), duration=duration, limits=limits,
                        **search)


def tune_gains(cfg: RobustConfig, progress: Any = None, pool: Any = None) -> RobustResult:
    """Run the robust search (``pool``: robust.pool.worker_pool's); NothingRobust when no gain set
    held on every neighbour."""
    from .robust.search import tune
    try:
        return tune(cfg, progress, pool)
    except RuntimeError as exc:
        raise NothingRobust(str(exc)) from None


def record(result: RobustResult, cfg: RobustConfig, vehicle_path: str | Path, sha256: str,
           command: str) -> TunedGains:
    """The tuned gains with their record: vehicle file, its hash, the ensemble, the command."""
    weighed = [label if w == 1.0 else f"{label} (weight {w:g})"
               for label, w in zip(result.references, cfg.reference_weights(), strict=True)]
    lines = [f"robust tune for the vehicle file {vehicle_path} (sha256 {sha256[:16]}...)",
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
                   vehicle_sha256=sha256)
