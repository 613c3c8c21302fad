"""Vehicle files: the identified inner loops of one rover, as ``companion identify`` writes them.

A small TOML file, units in the key names, a header saying how it was made::

    # pzc-rover vehicle file, written by `companion identify sitl.tlog --out vehicle.toml`
    schema = "pzc-rover/vehicle/1"
    name = "ardupilot-skid"
    autopilot = "ardupilot"       # the autopilot profile that flies it (companion.profiles)
    steering = "skid"             # its steering kind (companion.profiles)
    d_cen_m = 0.0

    [speed]                       # the speed channel: delay -> clamp -> rate limit -> lag
    delay_s = 0.06
    lag_s = 0.30                  # time constant (1 / w_c)
    max_m_s = 4.0
    accel_max_m_s2 = 1.0          # while |v| grows
    decel_max_m_s2 = 1.0          # while |v| shrinks
    overshoot = 0.2               # share the speed overshoots a change by (ArduPilot's PI)
    overshoot_s = 1.0             # and how long it takes to come back (time constant)

    [turn_rate]
    delay_s = 0.04
    lag_s = 0.05
    max_rad_s = 2.094
    accel_max_rad_s2 = 2.09
    decel_max_rad_s2 = 2.09
    lat_accel_max_m_s2 = 5.88     # turn rate <= this / max(|v|, 1 m/s) (ATC_TURN_MAX_G x g)
    overshoot = -0.3              # the rate loop's two time scales: share beyond (> 0) or short
    overshoot_s = 0.8             # of (< 0) the change at once; the rest at this time constant

    [coupling]
    turn_speed = 0.3              # share of top speed lost at full turn rate (skid-steer mixing)
    speed_turn = 0.15             # share of the turn-rate clamp lost at full speed

    [course]                      # optional: PX4's velocity-vector interface, Ackermann steering
    gain_1_s = 5.0                # PX4's course loop: turn rate per rad of course error (0: none)
    min_turn_radius_m = 0.56      # wheel base / tan(max steering angle) (a car; 0: turns in place)

    [estimate]                    # optional: the pose estimate's white noise at a stand still
    position_noise_m = 0.004      # (calibrate measures it; the tuner then simulates at least
    yaw_noise_rad = 0.001         # this much: companion.ident.noise)
    still_s = 12.0                # s of stand still it was measured over

    [fit]                         # optional: how well the model reproduced the log
    speed_rms_m_s = 0.05
    yaw_rate_rms_rad_s = 0.04

    [determined]                  # optional: per parameter, how it was set and how tightly
    speed_accel_max_m_s2 = "fitted 1.05, 1.01 to 1.09, by manoeuvre.tlog, track.tlog"

``autopilot`` and ``steering`` name the profiles that fly the vehicle (checked against the
registry where the vehicle is loaded, :mod:`companion.vehicle`); a file without them (written
before they existed) has them inferred from its model and says so.

``[course]`` is written only when set; a gain there makes it a PX4 vehicle (a turning radius
alone is a car driven by speed / turn-rate setpoints: ArduPilot's Ackermann rover): the
companion's velocity vector u_p is the input, |u_p| through the speed channel and the course atan2(u_p) through PX4's
proportional course loop into the turn-rate channel, which an Ackermann rover's minimum turning
radius also clamps (:class:`companion.sim.plant.RoverParams`, ``course_gain`` and
``min_turn_radius``). Every key but ``schema`` has a default (the paper's plant: no delay, 0.05 s lag, no limits), so
the paper's rover is the file with nothing in it. ``[fit]``, ``[determined]`` and ``[source]`` are
free-form records (numbers and strings) kept for people. :class:`companion.sim.plant.RoverParams` is what
the simulation uses; :func:`to_params` / :func:`from_params` convert.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import UserError
from .gains import read_toml
from .plant import RoverParams

SCHEMA = "pzc-rover/vehicle/1"
MIN_LAG = 1e-3          # s: a lag shorter than a plant step is no lag

# section -> key -> (RoverParams field, kind); kinds: "lag" (s -> bandwidth), "limit" (> 0, may
# be inf as "inf"), "delay" (>= 0), "share" (0..1), "signed" (-0.9..3: a share beyond or short
# of one), "length" (any finite).
_CHANNELS: dict[str, dict[str, tuple[str, str]]] = {
    "speed": {"delay_s": ("speed_delay", "delay"), "lag_s": ("w_c", "lag"),
              "max_m_s": ("max_speed", "limit"), "accel_max_m_s2": ("max_accel", "limit"),
              "decel_max_m_s2": ("max_decel", "limit"),
              "overshoot": ("speed_overshoot", "share"),
              "overshoot_s": ("speed_overshoot_s", "limit")},
    "turn_rate": {"delay_s": ("yaw_delay", "delay"), "lag_s": ("w_c_yaw", "lag"),
                  "max_rad_s": ("max_yaw_rate", "limit"),
                  "accel_max_rad_s2": ("max_yaw_accel", "limit"),
                  "decel_max_rad_s2": ("max_yaw_decel", "limit"),
                  "lat_accel_max_m_s2": ("max_lat_accel", "limit"),
                  "overshoot": ("yaw_overshoot", "signed"),
                  "overshoot_s": ("yaw_overshoot_s", "limit")},
    "coupling": {"turn_speed": ("turn_speed_coupling", "share"),
                 "speed_turn": ("speed_turn_coupling", "share")},
    "course": {"gain_1_s": ("course_gain", "nonneg"),
               "min_turn_radius_m": ("min_turn_radius", "nonneg")},
}
_OPTIONAL = ("course",)       # written only when one of its values is set
_RECORDS = ("fit", "determined", "source")
# [estimate]: key -> the largest value that is still a pose estimate worth tuning for
_ESTIMATE = {"position_noise_m": 1.0, "yaw_noise_rad": 0.5, "still_s": math.inf}


@dataclass(frozen=True)
class VehicleFile:
    params: RoverParams
    name: str = ""
    header: str = ""                                   # comment lines, without the '# '
    fit: dict[str, Any] = field(default_factory=dict)
    source: dict[str, Any] = field(default_factory=dict)
    path: str = ""
    determined: dict[str, Any] = field(default_factory=dict)
    autopilot: str = ""                                # a profile's name; "": not named
    steering: str = ""                                 # a steering kind's name; "": not named
    # [estimate]: the pose estimate's white noise at a stand still (empty: not measured)
    estimate: dict[str, float] = field(default_factory=dict)


def _value(where: str, key: str, value: Any, kind: str) -> float:
    if kind == "limit" and value == "inf":
        return math.inf
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise UserError(f"{where}.{key}: must be a finite number, not {value!r}")
    value = float(value)
    bad = {"lag": value < 0, "limit": value <= 0, "delay": value < 0 or value > 5.0,
           "share": not 0.0 <= value <= 1.0, "signed": not -0.9 <= value <= 3.0,
           "length": False, "nonneg": value < 0}[kind]
    if bad:
        want = {"lag": ">= 0", "limit": "> 0 (or \"inf\")", "delay": "between 0 and 5 s",
                "share": "between 0 and 1", "signed": "between -0.9 and 3", "length": "",
                "nonneg": ">= 0"}[kind]
        raise UserError(f"{where}.{key}: must be {want}, not {value!r}")
    return value


def parse(data: dict[str, Any], where: str) -> VehicleFile:
    """A parsed vehicle table to a :class:`VehicleFile`; one-line UserError naming the key."""
    if data.get("schema") != SCHEMA:
        raise UserError(f"{where}: schema: must be \"{SCHEMA}\", not {data.get('schema')!r}")
    known = {"schema", "name", "autopilot", "steering", "d_cen_m", "estimate", *_CHANNELS,
             *_RECORDS}
    for key in data:
        if key not in known:
            raise UserError(f"{where}: unknown key '{key}'")
    kwargs: dict[str, float] = {}
    if "d_cen_m" in data:
        kwargs["d_cen"] = _value(where, "d_cen_m", data["d_cen_m"], "length")
    for section, keys in _CHANNELS.items():
        table = data.get(section, {})
        if not isinstance(table, dict):
            raise UserError(f"{where}: '{section}' must be a table")
        for key, value in table.items():
            if key not in keys:
                raise UserError(f"{where}: unknown key '{section}.{key}'")
            name, kind = keys[key]
            number = _value(f"{where}: {section}", key, value, kind)
            kwargs[name] = 1.0 / max(number, MIN_LAG) if kind == "lag" else number
    for section in _RECORDS:
        if not isinstance(data.get(section, {}), dict):
            raise UserError(f"{where}: '{section}' must be a table")
    names = {}
    for key in ("name", "autopilot", "steering"):
        names[key] = data.get(key, "")
        if not isinstance(names[key], str):
            raise UserError(f"{where}: {key}: must be a string, not {names[key]!r}")
    defaults = RoverParams(w_c=1.0 / 0.05)
    return VehicleFile(params=defaults.with_(**kwargs), fit=dict(data.get("fit", {})),
                       source=dict(data.get("source", {})), path=where,
                       determined=dict(data.get("determined", {})),
                       estimate=_estimate(data.get("estimate", {}), where), **names)


def _estimate(table: Any, where: str) -> dict[str, float]:
    if not isinstance(table, dict):
        raise UserError(f"{where}: 'estimate' must be a table")
    out = {}
    for key, value in table.items():
        if key not in _ESTIMATE:
            raise UserError(f"{where}: unknown key 'estimate.{key}'")
        number = _value(f"{where}: estimate", key, value, "nonneg")
        if number > _ESTIMATE[key]:
            raise UserError(f"{where}: estimate.{key}: must be at most {_ESTIMATE[key]:g}, "
                            f"not {value!r}")
        out[key] = number
    return out


def loads(text: str, where: str) -> VehicleFile:
    """A vehicle file's text (read from ``where``); any problem is one line naming the file
    and the key."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{where}: not valid TOML: {exc}") from None
    return parse(data, where)


def load(path: str | Path) -> VehicleFile:
    """Read a vehicle file; any problem is one line naming the file and the key. Commands
    load a vehicle once (:func:`companion.app.vehicle.load`); the plant reads its own here."""
    return parse(read_toml(path, "no such vehicle file"), str(path))


def _fmt(value: Any) -> str:
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, bool):
        return "true" if value else "false"
    value = float(value)
    return '"inf"' if math.isinf(value) else f"{value:.6g}"


def dumps(vehicle: VehicleFile) -> str:
    """The TOML text of a vehicle file (what :func:`load` reads back to the same parameters)."""
    p = vehicle.params
    lines = [f"# {line}" for line in (vehicle.header or "pzc-rover vehicle file").splitlines()]
    lines += [f'schema = "{SCHEMA}"', f"name = {_fmt(vehicle.name)}"]
    lines += [f"{key} = {_fmt(value)}" for key, value in
              (("autopilot", vehicle.autopilot), ("steering", vehicle.steering)) if value]
    lines += [f"d_cen_m = {_fmt(p.d_cen)}"]
    values = {"speed_delay": p.speed_delay, "w_c": 1.0 / p.w_c, "max_speed": p.max_speed,
              "max_accel": p.max_accel, "max_decel": p.decel, "yaw_delay": p.yaw_delay,
              "w_c_yaw": 1.0 / p.yaw_bandwidth, "max_yaw_rate": p.max_yaw_rate,
              "max_yaw_accel": p.max_yaw_accel, "max_yaw_decel": p.yaw_decel,
              "turn_speed_coupling": p.turn_speed_coupling,
              "speed_turn_coupling": p.speed_turn_coupling, "course_gain": p.course_gain,
              "min_turn_radius": p.min_turn_radius, "max_lat_accel": p.max_lat_accel,
              "speed_overshoot": p.speed_overshoot, "speed_overshoot_s": p.speed_overshoot_s,
              "yaw_overshoot": p.yaw_overshoot, "yaw_overshoot_s": p.yaw_overshoot_s}
    for section, keys in _CHANNELS.items():
        if section in _OPTIONAL and not any(float(values[name]) for name, _ in keys.values()):
            continue
        lines += ["", f"[{section}]"]
        lines += [f"{key} = {_fmt(values[name])}" for key, (name, _) in keys.items()]
    if vehicle.estimate:
        lines += ["", "[estimate]"] + [f"{k} = {_fmt(v)}" for k, v in vehicle.estimate.items()]
    for section in _RECORDS:
        record = getattr(vehicle, section)
        if record:
            lines += ["", f"[{section}]"] + [f"{k} = {_fmt(v)}" for k, v in record.items()]
    return "\n".join(lines) + "\n"


def save(vehicle: VehicleFile, path: str | Path) -> None:
    try:
        Path(path).write_text(dumps(vehicle))
    except OSError as exc:
        raise UserError(f"{path}: cannot write: {exc}") from None


VEHICLES_DIR = Path(__file__).parent / "vehicles"
# Named vehicles: the paper's rover, the linear stock-rover approximation, and identified files
# shipped in ``companion/sim/vehicles/`` (a name maps to ``<name with _>.toml``).
PRESETS = ("paper", "stock", "ardupilot-skid")


def preset_path(name: str) -> Path | None:
    """The shipped vehicle file behind a preset name (None for the built-in models)."""
    return VEHICLES_DIR / f"{name.replace('-', '_')}.toml" if name not in ("paper", "stock") \
        else None


def preset(name: str) -> RoverParams:
    """The parameters of a named vehicle (:data:`PRESETS`)."""
    if name == "paper":
        return RoverParams.paper()
    if name == "stock":
        return RoverParams.stock_rover()
    if name in PRESETS:
        return load(VEHICLES_DIR / f"{name.replace('-', '_')}.toml").params
    raise UserError(f"unknown vehicle preset {name!r} (known: {', '.join(PRESETS)})")
