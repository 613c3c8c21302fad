"""A vehicle file loaded once, where a command starts: the one place below the commands that
opens a vehicle file (and the gains files beside it).

:func:`load` reads the file's bytes and the gains files in its folder tuned for them, and
builds the :class:`companion.vehicle.Vehicle` record every layer below is handed;
:func:`gains_for` finds its gains for a loop rate, or tunes them now (the tuner is imported
only then) and stores them beside it for next time.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..errors import UserError
from ..sim import gains as gains_mod
from ..sim import vehicle_file
from ..sim.gains import TunedGains
from ..vehicle import Vehicle, from_bytes

Log = Callable[[str], None]


def load(path: str | Path) -> Vehicle:
    """The vehicle file at ``path`` with the gains tuned for it beside it; any problem with the
    file is one line naming it (UserError)."""
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise UserError(f"{path}: no such vehicle file") from None
    except OSError as exc:
        raise UserError(f"{path}: cannot read: {exc}") from None
    return from_bytes(data, str(path), _gains_beside(Path(path), data))


def bundled(name: str) -> Vehicle | None:
    """A vehicle file shipped with the companion (``companion/sim/vehicles/``), by its preset
    name; None for a built-in model (``paper``, ``stock``)."""
    path = vehicle_file.preset_path(name)
    return load(path) if path is not None else None


def bundled_for(autopilot: Any) -> dict[str, Vehicle]:
    """The bundled vehicles identified on this autopilot (its profile's ``presets``), loaded:
    what ``run`` without a vehicle file matches the live vehicle against."""
    return {name: v for name in autopilot.presets if (v := bundled(name)) is not None}


def bundled_all() -> dict[str, Vehicle]:
    """Every autopilot's bundled vehicles, loaded, by preset name (a live session matches a
    vehicle flown without a file against its autopilot's, once it knows the autopilot)."""
    from .. import profiles
    return {name: v for p in profiles.AUTOPILOTS.values() for name, v in bundled_for(p).items()}


def _gains_beside(path: Path, data: bytes) -> tuple[TunedGains, ...]:
    """Gains files in the vehicle file's folder that name these bytes' SHA-256."""
    from ..vehicle import digest
    sha, found = digest(data), []
    for other in sorted(path.resolve().parent.glob("*.toml")):
        if other == path.resolve():
            continue
        try:
            text = other.read_text()
        except (OSError, UnicodeDecodeError):
            continue
        if sha not in text:                 # cheap filter before parsing
            continue
        try:
            found.append(gains_mod.load(other))
        except UserError:
            continue
    return tuple(found)


def path_beside(vehicle: Vehicle, rate: float) -> Path:
    """Where gains tuned on the spot are kept: ``gains.toml`` beside ``vehicle.toml`` (what
    ``companion calibrate`` writes), else ``<stem>.gains-<rate>hz.toml``."""
    path = Path(vehicle.path)
    plain = path.with_name("gains.toml")
    if path.name == "vehicle.toml" and not plain.exists():
        return plain
    return path.with_name(f"{path.stem}.gains-{rate:g}hz.toml")


def tuner_config(vehicle: Vehicle, rate: float, references: Any = (), duration: float = 60.0,
                 **search: Any):
    """The robust tuner's configuration for ``vehicle``: its model and limits, its autopilot's
    and steering kind's settings, then ``search`` (population, rounds, ...) over them. Every
    tune of a vehicle file goes through here: tune, calibrate, run and the rest."""
    from ..sim.vehicle_gains import config_for
    return config_for(vehicle.params, vehicle.limits, rate, references, duration,
                      **{**vehicle.tune_settings, **search})


def tune_and_record(vehicle: Vehicle, rate: float, command: str, progress: Any = None,
                    pool: Any = None, **search: Any) -> TunedGains:
    """Gains tuned now for ``vehicle`` at ``rate``, with their record (not stored)."""
    from ..sim.vehicle_gains import record, tune_gains
    cfg = tuner_config(vehicle, rate, **search)
    try:
        result = tune_gains(cfg, progress, pool)
    except UserError as exc:
        raise type(exc)(f"{vehicle.path}: {exc}") from None
    return record(result, cfg, vehicle.path, vehicle.sha256, command)


def gains_for(vehicle: Vehicle, rate: float, command: str, show_bar: bool, log: Log,
              pool: Any = None, **search: Any) -> TunedGains:
    """The vehicle's gains at ``rate``: found beside it, else tuned now (with a progress bar;
    ``search``: the tuner's population, rounds, ...; ``pool``: robust.pool.worker_pool's) and stored
    there."""
    found = vehicle.gains_at(rate)
    if found is not None:
        log(f"gains tuned for {vehicle.path}: {found.source}")
        return found
    log(f"no gains tuned for {vehicle.path} at {rate:g} Hz yet: tuning them now (about a minute)")
    from ..progress import progress_bar
    with progress_bar(f"tuning for {Path(vehicle.path).name}", show_bar) as progress:
        tuned = tune_and_record(vehicle, rate, command, progress, pool, **search)
    out = path_beside(vehicle, rate)
    try:
        tuned.save(out)
    except OSError as exc:
        log(f"could not store the gains beside the vehicle ({out}: {exc}); using them anyway")
        return replace(tuned, source=f"tuned now for {vehicle.path}")
    log(f"gains tuned for {vehicle.path} stored in {out}")
    return replace(tuned, source=str(out))


def known(vehicle: Vehicle, gains: TunedGains | None = None):
    """What the flight's policy knows of ``vehicle`` (companion.live.policy.KnownVehicle)."""
    from ..live.policy import KnownVehicle
    return KnownVehicle(gains=gains, limits=vehicle.limits, w_c=float(vehicle.params.w_c),
                        d_cen=float(vehicle.params.d_cen))


def for_flight(flag: str | None, mission: Any) -> tuple[Any, Vehicle | None]:
    """(the mission with its ``[vehicle] file``'s model, the vehicle a command flies: ``flag``
    (--vehicle), else the mission's ``[vehicle] file``), each file loaded once."""
    named = None
    if mission is not None and mission.vehicle_file is not None:
        try:
            named = load(mission.vehicle_file)
        except UserError as err:   # name the mission file and key too, still on one line
            raise UserError(f"{mission.source}: [vehicle] file: {err}") from None
        mission = mission.with_vehicle_file(named.params)
    if flag is None:
        return mission, named
    if named is not None and Path(flag).resolve() == Path(named.path).resolve():
        return mission, named
    return mission, load(flag)
