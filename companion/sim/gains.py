"""Tuned-gains files: what ``companion tune`` writes and every other command reads.

A small TOML file::

    # written by `companion tune`
    rate_hz = 40.0          # controller rate the gains were tuned for
    w_c = 1.2               # actuator bandwidth (rad/s) of the tuning plant
    d_cen = 0.0
    cost = 12.3             # tuner's objective (sum of f_cost over its reference speeds)

    [filter]                # paper: k_{d,f}, lambda_f
    k_df = 300.0
    lambda_f = 40.0

    [pzc]                   # paper: k_{d,c}, lambda_c; the rest are extensions (see companion.core.pzc)
    k_dc = 4.0
    lambda_c = 2.0
    k_dc_yaw = 8.0
    lambda_c_yaw = 3.0
    velocity_ff = true
    heading_rate_ff = true
    accel_ff = 0.8          # s, reference-acceleration feed-forward (about 1 / w_c)
    lead_tau = 0.8          # s, actuator lead (companion.core.lead): the actuator's 1 / w_c
    lead_max_gain = 8.0
    speed_law = "projected"

Files for the rates and actuators we ship with live in ``companion/sim/tuned/``.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from ..core.filter import FilterGains
from ..core.pzc import PZCGains
from ..errors import UserError

TUNED_DIR = Path(__file__).parent / "tuned"


# Law settings newer than the first gains files: written only when on (not at their default)
OMITTED_WHEN_OFF = ("min_progress", "course_tau", "brake_integrate", "approach_cone",
                    "predict_s", "cancel_overshoot", "cancel_overshoot_s")


@dataclass(frozen=True)
class TunedGains:
    filter: FilterGains
    pzc: PZCGains
    rate_hz: float
    w_c: float
    d_cen: float = 0.0
    cost: float | None = None
    source: str = ""
    header: str = ""                   # comment lines: how the gains were made
    vehicle_file: str | None = None    # the vehicle file they were tuned for (companion tune --vehicle)
    vehicle_sha256: str | None = None  # of that file's bytes: gains follow the vehicle they fit

    def to_toml(self) -> str:
        lines = ["# written by `companion tune`"]
        lines += [f"# {line}" for line in self.header.splitlines()]
        lines += [f"rate_hz = {self.rate_hz!r}", f"w_c = {self.w_c!r}", f"d_cen = {self.d_cen!r}"]
        if self.cost is not None:
            lines.append(f"cost = {self.cost!r}")
        if self.vehicle_file is not None:
            lines.append("vehicle_file = " + json.dumps(self.vehicle_file))
            lines.append(f'vehicle_sha256 = "{self.vehicle_sha256}"')
        lines += ["", "[filter]", f"k_df = {float(self.filter.k_df)!r}",
                  f"lambda_f = {float(self.filter.lambda_f)!r}", "", "[pzc]"]
        for f in fields(PZCGains):
            value = getattr(self.pzc, f.name)
            if value is None or (f.name in OMITTED_WHEN_OFF and value == f.default):
                continue              # off: not written (older files stay as they were)
            if f.name in ("velocity_ff", "heading_rate_ff"):
                lines.append(f"{f.name} = {'true' if value else 'false'}")
            elif isinstance(value, str):
                lines.append(f'{f.name} = "{value}"')
            else:
                lines.append(f"{f.name} = {float(value)!r}")
        return "\n".join(lines) + "\n"

    def save(self, path: str | Path) -> None:
        Path(path).write_text(self.to_toml())


def _number(table: dict, key: str, where: str, positive: bool = True) -> float:
    if key not in table:
        raise UserError(f"{where}: missing key '{key}'")
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise UserError(f"{where}: '{key}' must be a finite number, not {value!r}")
    if positive and value <= 0:
        raise UserError(f"{where}: '{key}' must be > 0, not {value!r}")
    return float(value)


def parse(data: dict, where: str) -> TunedGains:
    """Validate a parsed gains table (also used for a mission file's gains section)."""
    known_top = {"rate_hz", "w_c", "d_cen", "cost", "filter", "pzc", "vehicle_file",
                 "vehicle_sha256"}
    for key in data:
        if key not in known_top:
            raise UserError(f"{where}: unknown key '{key}'")
    filt = data.get("filter", {})
    pzc = data.get("pzc", {})
    if not isinstance(filt, dict) or not isinstance(pzc, dict):
        raise UserError(f"{where}: 'filter' and 'pzc' must be tables")
    for key in filt:
        if key not in ("k_df", "lambda_f"):
            raise UserError(f"{where}: unknown key 'filter.{key}'")
    pzc_names = {f.name for f in fields(PZCGains)}
    for key in pzc:
        if key not in pzc_names:
            raise UserError(f"{where}: unknown key 'pzc.{key}'")
    fg = FilterGains(_number(filt, "k_df", f"{where}: filter"),
                     _number(filt, "lambda_f", f"{where}: filter"))
    kwargs: dict[str, Any] = {"k_dc": _number(pzc, "k_dc", f"{where}: pzc"),
              "lambda_c": _number(pzc, "lambda_c", f"{where}: pzc")}
    for key in ("k_dc_yaw", "lambda_c_yaw"):
        if key in pzc:
            kwargs[key] = _number(pzc, key, f"{where}: pzc")
    for key in ("lead_tau", "lead_max_gain"):
        if key in pzc:
            kwargs[key] = _number(pzc, key, f"{where}: pzc", positive=False)
            if kwargs[key] < (0 if key == "lead_tau" else 1):
                raise UserError(f"{where}: pzc.{key} must be >= {0 if key == 'lead_tau' else 1}, "
                                f"not {kwargs[key]!r}")
    # seconds and accelerations that are off at 0 (accel_ff_turn absent: as accel_ff)
    for key in ("accel_ff", "accel_ff_turn", "brake_accel", "brake_yaw_accel", "min_progress",
                "course_tau", "approach_cone", "predict_s", "cancel_overshoot"):
        if key in pzc:
            kwargs[key] = _number(pzc, key, f"{where}: pzc", positive=False)
            if kwargs[key] < 0:
                raise UserError(f"{where}: pzc.{key} must be >= 0, not {kwargs[key]!r}")
    if "cancel_overshoot_s" in pzc:                 # a time constant: > 0
        kwargs["cancel_overshoot_s"] = _number(pzc, "cancel_overshoot_s", f"{where}: pzc")
    if "brake_integrate" in pzc:
        kwargs["brake_integrate"] = _number(pzc, "brake_integrate", f"{where}: pzc")
        if kwargs["brake_integrate"] < 1:
            raise UserError(f"{where}: pzc.brake_integrate must be >= 1 (knees), not "
                            f"{kwargs['brake_integrate']!r}")
    if kwargs.get("approach_cone", 0.0) >= 0.5 * math.pi:
        raise UserError(f"{where}: pzc.approach_cone must be below pi/2 rad (90 deg), not "
                        f"{kwargs['approach_cone']!r}")
    for key in ("velocity_ff", "heading_rate_ff"):
        if key in pzc:
            if not isinstance(pzc[key], bool):
                raise UserError(f"{where}: pzc.{key} must be true or false, not {pzc[key]!r}")
            kwargs[key] = pzc[key]
    if "speed_law" in pzc:
        if pzc["speed_law"] not in ("projected", "paper"):
            raise UserError(f"{where}: pzc.speed_law must be \"projected\" or \"paper\", "
                            f"not {pzc['speed_law']!r}")
        kwargs["speed_law"] = pzc["speed_law"]
    return TunedGains(
        filter=fg, pzc=PZCGains(**kwargs),
        rate_hz=_number(data, "rate_hz", where) if "rate_hz" in data else math.nan,
        w_c=_number(data, "w_c", where) if "w_c" in data else math.nan,
        d_cen=_number(data, "d_cen", where, positive=False) if "d_cen" in data else 0.0,
        cost=_number(data, "cost", where, positive=False) if "cost" in data else None,
        source=where, vehicle_file=_text(data, "vehicle_file", where),
        vehicle_sha256=_text(data, "vehicle_sha256", where))


def _text(table: dict, key: str, where: str) -> str | None:
    if key not in table:
        return None
    if not isinstance(table[key], str):
        raise UserError(f"{where}: '{key}' must be a string, not {table[key]!r}")
    return table[key]


def read_toml(path: str | Path, missing: str = "no such file") -> dict:
    """A TOML file's table; a missing, unreadable or malformed file is one line (UserError)."""
    path = Path(path)
    try:
        return tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise UserError(f"{path}: {missing}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{path}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{path}: not valid TOML: {exc}") from None


def load(path: str | Path) -> TunedGains:
    """Read a tuned-gains file; any problem is a one-line :class:`UserError` naming file and key."""
    return parse(read_toml(path), str(path))


def tuned_path(rate_hz: float, w_c: float, d_cen: float = 0.0) -> Path:
    """Where the shipped gains for this rate, actuator bandwidth and d_cen live."""
    name = f"rate{rate_hz:g}_wc{w_c:g}" + (f"_dcen{d_cen:g}" if d_cen else "") + ".toml"
    return TUNED_DIR / name


def find_tuned(rate_hz: float, w_c: float = 20.0, d_cen: float = 0.0) -> TunedGains | None:
    """The shipped tuned gains for exactly this rate and w_c (and d_cen), or None."""
    path = tuned_path(rate_hz, w_c, d_cen)
    return load(path) if path.exists() else None
