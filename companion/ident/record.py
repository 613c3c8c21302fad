"""What a vehicle file written by ``companion identify`` records, and the figures it reports.

Turns a :class:`companion.ident.fit.Fit` into a :class:`companion.sim.vehicle_file.VehicleFile`
whose header says how it was made (the command, the log(s), the priors, what the log did not
determine) and whose ``[fit]`` / ``[source]`` records hold the RMS figures and the inputs, and
into the parameter table the command prints and its ``--json`` object carries (the vehicle
file's own section / key names and units).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import profiles
from ..profiles.autopilot import AutopilotProfile
from ..sim.plant import RoverParams
from ..sim.vehicle_file import VehicleFile
from .fit import Fit
from .noise import EstimateNoise
from .priors import COURSE_FIELDS, FILE_NAMES, SPEED_FIELDS, YAW_FIELDS, Priors
from .series import Series


@dataclass
class Report:
    """Everything one identification produced (what is printed, written and returned)."""

    fit: Fit
    priors: Priors
    series: Series
    log: str                       # the log's path; several fitted together: joined by " + "
    fit_time_s: float
    out: str = ""
    check_log: str | None = None
    check_rms: tuple[float, float] | None = None
    autopilot: dict[str, float] = field(default_factory=dict)
    figures: list[str] = field(default_factory=list)
    command: str = ""
    parts: list[Series] = field(default_factory=list)    # each log's series, when several
    fit_cpu_s: float = 0.0         # this process's CPU seconds for the fit
    # the autopilot the log was recorded with (its heartbeat; a log that does not say: the
    # default): its priors, what calibrate holds the fit to
    profile: AutopilotProfile = field(default_factory=profiles.default_autopilot)
    noise: EstimateNoise | None = None     # the pose estimate's, at a stand still in the log


def file_value(params: RoverParams, name: str) -> float:
    """A RoverParams field in the vehicle file's unit (lags as time constants)."""
    if name == "w_c":
        return 1.0 / params.w_c
    if name == "w_c_yaw":
        return 1.0 / params.yaw_bandwidth
    if name == "max_decel":
        return params.decel
    if name == "max_yaw_decel":
        return params.yaw_decel
    return float(getattr(params, name))


def _number(value: float) -> float | None:
    return value if math.isfinite(value) else None


def parameter_table(params: RoverParams, autopilot: AutopilotProfile | None = None
                    ) -> dict[str, dict[str, float | None]]:
    """{"speed": {"delay_s": ...}, "turn_rate": {...}, "coupling": {...}} (None: no limit),
    and "course" where the profiles describe the vehicle by its fields (the ``autopilot``'s
    course loop, found from the model when not given; a steering kind's turning radius)."""
    out: dict[str, dict[str, float | None]] = {}
    for name in SPEED_FIELDS + YAW_FIELDS:        # the vehicle file's order: turn_speed first
        section, key = FILE_NAMES[name].split(".")
        out.setdefault(section, {})[key] = _number(file_value(params, name))
    table = {k: out[k] for k in ("speed", "turn_rate", "coupling")}
    table["turn_rate"]["lat_accel_max_m_s2"] = _number(float(params.max_lat_accel))
    autopilot = autopilot or profiles.autopilot_of_model(params)
    described = {*autopilot.model_fields, *profiles.steering_of_model(params).model_fields}
    if described & set(COURSE_FIELDS):
        table["course"] = {"gain_1_s": float(params.course_gain),
                           "min_turn_radius_m": float(params.min_turn_radius)}
    return table


def undetermined(report: Report) -> list[str]:
    """Vehicle-file names of what the log did not determine, with what was used."""
    lines = []
    for name in report.fit.undetermined:
        status = report.fit.status[name]
        value = file_value(report.fit.params, name)
        why = (f"prior, {report.priors.describe(name)}" if status == "prior"
               else "the log bounds it; its prior contradicts the log")
        lines.append(f"{FILE_NAMES[name]} = {value:.4g} ({why})")
    return lines


def _log_names(report: Report) -> list[str]:
    return [Path(p).name for p in report.log.split(" + ")]


def _file_range(name: str, lo: float, hi: float) -> tuple[float, float]:
    """A RoverParams range in the vehicle file's unit (a bandwidth range as time constants)."""
    if name in ("w_c", "w_c_yaw"):
        return (1.0 / hi if 0 < hi < math.inf else -math.inf), (1.0 / lo if lo > 0 else math.inf)
    return lo, hi


def determined(report: Report) -> dict[str, dict[str, Any]]:
    """Per parameter (vehicle-file names): how it was set (fitted / prior / bound), its value,
    and for a fitted one the range every log allows (within 2 % of its RMS, the others held;
    None: the scan's end, only bounded on that side) and the logs that determine it."""
    f, names = report.fit, _log_names(report)
    out: dict[str, dict[str, Any]] = {}
    for name, status in f.status.items():
        entry: dict[str, Any] = {"status": status,
                                 "value": _number(file_value(f.params, name))}
        d = f.determined.get(name)
        if d is not None:
            lo, hi = _file_range(name, d.lo, d.hi)
            entry.update(low=_number(lo), high=_number(hi),
                         logs=[names[k] if k < len(names) else str(k) for k in d.logs])
        out[FILE_NAMES[name]] = entry
    return out


def _determined_line(entry: dict[str, Any]) -> str:
    """``fitted 1.05, 1.01 to 1.09, by LOG, LOG`` (``at most`` / ``at least`` for a range the
    scan did not close on one side); ``prior 3`` or ``bound 3`` for what no log determined."""
    text = f"{entry['status']} " + (f"{entry['value']:.4g}" if entry["value"] is not None
                                   else "none")
    if "low" in entry:
        lo, hi = entry["low"], entry["high"]
        span = (f"at most {hi:.4g}" if lo is None and hi is not None else
                f"at least {lo:.4g}" if hi is None and lo is not None else
                "unbounded" if lo is None else f"{lo:.4g} to {hi:.4g}")
        text += f", {span}, by {', '.join(entry['logs']) or 'no single log'}"
    return text


def as_dict(report: Report) -> dict[str, Any]:
    """The ``--json`` object (without the live flight's part)."""
    f = report.fit
    return {
        "schema": "pzc-rover/identify/1",
        "out": report.out,
        "log": report.log,
        "samples": int(len(report.series.t)),
        "duration_s": report.series.duration,
        "fit_time_s": report.fit_time_s,
        "evaluations": f.evaluations,
        "params": parameter_table(f.params, report.profile),
        "rms": {"speed_m_s": f.speed_rms, "yaw_rate_rad_s": f.yaw_rate_rms},
        "check": (None if report.check_rms is None else
                  {"log": report.check_log, "speed_m_s": report.check_rms[0],
                   "yaw_rate_rad_s": report.check_rms[1]}),
        "undetermined": [FILE_NAMES[name] for name in f.undetermined],
        "status": {FILE_NAMES[name]: s for name, s in f.status.items()},
        "determined": determined(report),
        "priors": {FILE_NAMES[name]: {"value": _number(file_value(report.priors.params, name))
                                      if getattr(report.priors.params, name) is not None
                                      else None,
                                      "source": report.priors.describe(name)}
                   for name in YAW_FIELDS + SPEED_FIELDS},
        "autopilot_params": report.autopilot,
        "figures": report.figures,
        "estimate_noise": (None if report.noise is None else
                           {"position_m": report.noise.position_m,
                            "yaw_rad": report.noise.yaw_rad, "samples": report.noise.samples,
                            "still_s": report.noise.seconds}),
    }


def vehicle_file(report: Report, name: str) -> VehicleFile:
    f = report.fit
    header = [f"pzc-rover vehicle file, written by `{report.command}`" if report.command
              else "pzc-rover vehicle file, written by `companion identify`",
              f"fitted to {report.log} ({len(report.series.t)} samples, "
              f"{report.series.duration:.1f} s of setpoints) in {report.fit_time_s:.1f} s: "
              f"RMS speed {f.speed_rms:.3f} m/s, turn rate {f.yaw_rate_rms:.3f} rad/s"]
    if report.check_rms is not None:
        header.append(f"checked on {report.check_log}: RMS speed {report.check_rms[0]:.3f} m/s, "
                      f"turn rate {report.check_rms[1]:.3f} rad/s")
    header.append("autopilot parameters (priors): " + (
        ", ".join(f"{k} {v:g}" for k, v in sorted(report.autopilot.items()))
        if report.autopilot else "none known, default priors"))
    loose = undetermined(report)
    header.append("not determined by the log: " + ("; ".join(loose) if loose else "nothing"))
    header.append("d_cen is not identified (kept 0): measure the axle to the tracked point")
    fit_record: dict[str, Any] = {
        "speed_rms_m_s": f.speed_rms, "yaw_rate_rms_rad_s": f.yaw_rate_rms,
        "samples": len(report.series.t), "duration_s": report.series.duration,
        "fit_time_s": report.fit_time_s,
        "undetermined": ", ".join(FILE_NAMES[n] for n in f.undetermined)}
    if report.check_rms is not None:
        fit_record.update(check_speed_rms_m_s=report.check_rms[0],
                          check_yaw_rate_rms_rad_s=report.check_rms[1])
    source: dict[str, Any] = {"log": report.log}
    if report.check_log:
        source["check_log"] = report.check_log
    if report.command:
        source["command"] = report.command
    source.update(report.autopilot)
    record = {key.replace(".", "_"): _determined_line(entry)
              for key, entry in determined(report).items()}
    # the profiles that fly it, named in the file: the log's autopilot, the steering kind its
    # parameters show (else the fitted model's)
    steering = report.priors.steering or profiles.steering_of_model(f.params)
    n = report.noise
    estimate = ({"position_noise_m": n.position_m, "yaw_noise_rad": n.yaw_rad,
                 "still_s": n.seconds} if n is not None else {})
    return VehicleFile(params=f.params, name=name, header="\n".join(header), fit=fit_record,
                       source=source, determined=record, autopilot=report.profile.name,
                       steering=steering.name, estimate=estimate)
