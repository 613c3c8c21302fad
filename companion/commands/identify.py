"""``companion identify``: the vehicle model's inner loops, fitted to a flight log or to a short
manoeuvre flown on the spot.

    companion identify LOG [LOG ...] --out vehicle.toml [--check LOG2] [--plot DIR] [--json]
    companion identify --connect URL --out vehicle.toml [--arm] [--space R] [--json]

LOG is a .tlog (the companion's, or any with its SET_POSITION_TARGET_LOCAL_NED speed / turn-rate
setpoints) or the companion's .csv. The fit (:mod:`companion.ident.fit`) finds, per channel, the
delay, lag, clamp and acceleration / deceleration limits, and the skid-steer coupling, and
reports the RMS of the model's speed and turn rate against the measured ones; ``--check LOG2``
reports it on another log too. Several LOGs are fitted together, as one model that must
explain them all (a manoeuvre and a tracking flight: each determines what the other leaves
loose; ``calibrate`` refines this way). What the log does not determine takes its prior: the autopilot's
limit parameters when known (read live, or found in the .tlog), else stock ArduPilot values.

With ``--connect`` it flies the excitation manoeuvre (:mod:`companion.ident.excite`) in GUIDED
through the live loop of ``companion run`` (every failsafe, the flight logs, Zenoh, signing),
within ``--space`` metres of where the rover starts and for at most 90 s, then fits the .tlog
it wrote. On PX4 it reads PX4's rover parameters (``RO_*``, ``RA_*``: the priors), flies a
velocity-vector manoeuvre in OFFBOARD (speed steps on a gentle circle, course steps, slow tight
turns; nothing on the spot: an Ackermann rover cannot) and fits, besides the two channels,
PX4's course loop gain and the minimum turning radius (the vehicle file's ``[course]``).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..app.arguments import (
    add_limit_arguments,
    add_link_arguments,
    add_output_arguments,
    add_safety_arguments,
    add_timeout_arguments,
    add_zenoh_arguments,
    positive,
)
from ..errors import ExitCode, UserError

EPILOG = """\
exit codes: 0 done; 2 a user error (bad flag, a log that is malformed, too short or without
setpoints, no vehicle); 3 the manoeuvre was stopped by a fault (the rover is stopped: zero
setpoint, then HOLD; what was flown is still fitted when long enough).
"""

DEFAULT_SPACE = 10.0       # m: --space
MANOEUVRE_S = 85.0         # vehicle s of manoeuvre: the script (~75 s) and its returns, < 90 s


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "identify", help="fit the vehicle model to a flight log (or fly a manoeuvre and fit it)",
        description=__doc__.split("\n\n", 1)[1],
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("log_path", nargs="*", metavar="LOG",
                   help="flight log(s) to fit: .tlog or the companion's .csv; several are "
                        "fitted together (or use --connect)")
    p.add_argument("--out", required=True, metavar="FILE", help="vehicle file to write (TOML)")
    p.add_argument("--check", metavar="LOG2", help="another log to report the model's RMS on")
    p.add_argument("--plot", metavar="DIR", help="draw measured against model (PNG) into DIR")
    p.add_argument("--name", metavar="NAME", help="the vehicle's name in the file")
    add_live_arguments(p, "live: fly the excitation manoeuvre and fit it")
    p.set_defaults(func=run)


def add_live_arguments(p: argparse.ArgumentParser, title: str, required: bool = False) -> None:
    """The flags of a live identification (identify --connect, calibrate): the link, the
    manoeuvre's space and limits, run's timeouts, logs, signing, output and Zenoh flags."""
    add_link_arguments(p, title, required=required)
    live = p.add_argument_group("the manoeuvre")
    live.add_argument("--space", type=positive, default=DEFAULT_SPACE, metavar="M",
                      help=f"stay within M metres of the start (default {DEFAULT_SPACE:g})")
    add_limit_arguments(live)
    live.add_argument("--rate", type=positive, metavar="HZ",
                      help="telemetry / control rate to ask for (default 40)")
    add_timeout_arguments(p)
    add_safety_arguments(p)
    add_output_arguments(p, json_help="print one JSON object")
    add_zenoh_arguments(p)
    from ..app.config_file import add_config_arguments
    add_config_arguments(p)


@dataclass(frozen=True)
class FitOptions:
    """The offline half's flags: where the vehicle file goes and what else to report."""

    out: str                            # --out: the vehicle file to write
    check: str | None = None            # --check LOG2
    plot: str | None = None             # --plot DIR
    name: str | None = None             # --name


def fit_options(args: argparse.Namespace) -> FitOptions:
    return FitOptions(out=args.out, check=args.check, plot=args.plot, name=args.name)


def live_options(args: argparse.Namespace):
    """identify --connect's (and calibrate's) flight options: no gains, the manoeuvre's
    limits and rate."""
    from ..app.options import (
        FlightOptions,
        bus_options,
        link_config,
        log_options,
        output_options,
        runner_config,
    )
    from ..live.policy import GainOptions
    return FlightOptions(
        link=link_config(args), runner=runner_config(args),
        gains=GainOptions(rate=args.rate, max_speed=args.max_speed,
                          max_yaw_rate=args.max_yaw_rate),
        signing_key_file=args.signing_key, log=log_options(args),
        output=output_options(args, progress=False), bus=bus_options(args))


def _command_line() -> str:
    return "companion " + shlex.join(sys.argv[1:])


def _check_out(path: str) -> None:
    """Refuse an --out that cannot be written before anything is read, flown or fitted."""
    parent = Path(path).resolve().parent
    if not parent.is_dir():
        raise UserError(f"--out {path}: no such directory {parent}")
    if Path(path).is_dir():
        raise UserError(f"--out {path}: is a directory")


def run(args) -> int:
    if (not args.log_path) == (args.connect is None):
        raise UserError("give a LOG to fit or --connect URL to fly the manoeuvre (one of them)")
    _check_out(args.out)
    if args.connect is not None:
        return _live(args)
    report = identify_log(args.log_path, fit_options(args), {})
    _print(report, args.json)
    return ExitCode.OK


def identify_log(paths: str | list[str], fit_opts: FitOptions, autopilot: dict[str, float],
                 log=lambda text: None, label: str | None = None, prior=None):
    """Read, fit, check, write, plot: the offline half (the live half ends here too).
    Several ``paths`` are fitted together (:func:`companion.ident.series.join`). ``label`` names
    the log in the file when the path is not worth keeping (``--no-log``)."""
    from .. import profiles
    from ..ident.data import autopilot_params, log_autopilot, read_series
    from ..ident.fit import fit, rms
    from ..ident.noise import of_flight
    from ..ident.record import Report, vehicle_file
    from ..ident.series import join
    from ..sim.vehicle_file import save

    paths = [paths] if isinstance(paths, str) else list(paths)
    read = [read_series(path) for path in paths]
    parts = [series for series, _ in read]
    # the estimate's noise where the log stood still longest (None: nowhere long enough)
    noise = max(filter(None, (of_flight(flight) for _, flight in read)),
                key=lambda n: n.samples, default=None)
    try:
        series = join(parts)
    except ValueError as exc:
        raise UserError(f"LOG {' + '.join(paths)}: {exc}") from None
    check = read_series(fit_opts.check)[0] if fit_opts.check else None   # a bad one fails before the fit
    for path in paths:              # what was read live, then the first log's, win
        autopilot = {**autopilot_params(path, profiles.prior_params()), **autopilot}
    # the autopilot the logs were recorded with (their heartbeat): its parameters, its course loop
    profile = next(filter(None, map(log_autopilot, paths)), profiles.default_autopilot())
    priors = profile.priors_from(autopilot)
    if prior is not None:       # an earlier fit of this vehicle: what this log leaves open
        from dataclasses import fields

        from ..ident.priors import Priors
        priors = Priors(prior, {f.name: "the earlier fit" for f in fields(prior)})
    log(f"fitting {len(series.t)} samples ({series.duration:.1f} s)")
    t0, c0 = time.perf_counter(), time.process_time()
    result = fit(series, priors.params, progress=lambda what: log(f"fitting the {what}"))
    report = Report(result, priors, series, label or " + ".join(map(str, paths)),
                    time.perf_counter() - t0, out=fit_opts.out, parts=parts,
                    autopilot=autopilot, command=_command_line(),
                    fit_cpu_s=time.process_time() - c0, profile=profile, noise=noise)
    if check is not None:
        report.check_log, report.check_rms = str(fit_opts.check), rms(result.params, check)
    save(vehicle_file(report, fit_opts.name or Path(path).stem), fit_opts.out)
    if fit_opts.plot:
        report.figures = _plot(report, check, Path(fit_opts.plot))
    return report


def _plot(report, check, out: Path) -> list[str]:
    from ..ident.plot import plot_fit
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"--plot {out}: cannot create it: {exc.strerror}") from None
    f = report.fit
    figures = [plot_fit(report.series, f.params, out / "identify_fit.png",
                        f"{', '.join(Path(p).name for p in report.log.split(' + '))}: RMS speed {f.speed_rms:.3f} m/s, "
                        f"turn rate {f.yaw_rate_rms:.3f} rad/s")]
    if check is not None:
        figures.append(plot_fit(check, f.params, out / "identify_check.png",
                                f"check {Path(report.check_log).name}: RMS speed "
                                f"{report.check_rms[0]:.3f} m/s, turn rate "
                                f"{report.check_rms[1]:.3f} rad/s"))
    return figures


def _print(report, as_json: bool, flight: dict[str, Any] | None = None) -> None:
    from ..ident.record import as_dict, parameter_table, undetermined
    if as_json:
        d = as_dict(report)
        if flight is not None:
            d["flight"] = flight
        print(json.dumps(d), flush=True)
        return
    f = report.fit
    table = parameter_table(f.params, report.profile)

    def num(value, unit):
        return "none" if value is None else f"{value:.3g} {unit}"
    s, w = table["speed"], table["turn_rate"]
    lines = [
        f"vehicle     {report.out}",
        f"log         {report.log}: {len(report.series.t)} samples, "
        f"{report.series.duration:.1f} s; fitted in {report.fit_time_s:.1f} s",
        f"speed       delay {num(s['delay_s'], 's')}, lag {num(s['lag_s'], 's')}, "
        f"max {num(s['max_m_s'], 'm/s')}, accel {num(s['accel_max_m_s2'], 'm/s^2')}, "
        f"decel {num(s['decel_max_m_s2'], 'm/s^2')}",
        f"turn rate   delay {num(w['delay_s'], 's')}, lag {num(w['lag_s'], 's')}, "
        f"max {num(w['max_rad_s'], 'rad/s')}, accel {num(w['accel_max_rad_s2'], 'rad/s^2')}, "
        f"decel {num(w['decel_max_rad_s2'], 'rad/s^2')}",
        f"coupling    {table['coupling']['turn_speed']:.3g} of top speed lost at full turn rate, "
        f"{table['coupling'].get('speed_turn', 0.0):.3g} of the turn rate at full speed",
        f"RMS         speed {f.speed_rms:.3f} m/s, turn rate {f.yaw_rate_rms:.3f} rad/s "
        "(model minus measured, fitted log)",
    ]
    if report.check_rms is not None:
        lines.append(f"check       speed {report.check_rms[0]:.3f} m/s, turn rate "
                     f"{report.check_rms[1]:.3f} rad/s on {report.check_log}")
    lines.append("estimate    noise " + (report.noise.describe() if report.noise is not None
                                         else "not measured: the log never stood still 2 s"))
    loose = undetermined(report)
    lines.append("undetermined " + ("nothing: the log determined every parameter" if not loose
                                    else "by this log: " + "; ".join(loose)))
    if flight is not None:
        lines.append(f"flight      {flight['reason']} (exit {flight['exit_code']}), "
                     f"{flight['duration_s']:.1f} s, farthest {flight['max_distance_m']:.1f} m "
                     f"of {flight['space_m']:g} m, {flight['returns']} returns, HOLD "
                     + ("confirmed" if flight["hold_confirmed"] else "not confirmed"))
        for key in ("tlog", "csv"):
            if flight.get(key):
                lines.append(f"{key:<11} {flight[key]}")
    for figure in report.figures:
        lines.append(f"figure      {figure}")
    print("\n".join(lines), flush=True)


# --------------------------------------------------------------------------- live

def _mission(space: float):
    """The mission the live loop flies: the start point held for the manoeuvre's length."""
    from ..ident.excite import Home
    from ..mission import Mission
    return Mission(name="identify excitation",
                   description=f"companion identify: excitation manoeuvre within {space:g} m",
                   trajectory=Home(MANOEUVRE_S), duration=MANOEUVRE_S, rate_hz=None,
                   filter_gains=None, pzc_gains=None, limits=None, vehicle=None, frame="start",
                   source="companion identify", kind="excitation")


def _stopped_by(signal_name: str | None, reason: str) -> str | None:
    """Who cut the manoeuvre short on request: a signal (SIGTERM, SIGINT) or ``abort`` (from
    the control channel, during the setup or the flight), said as such; None otherwise."""
    if signal_name == "aborted" or (signal_name is None and reason == "aborted"):
        return "an abort request"
    return signal_name


def _live(args) -> int:
    code, report, flight = fly_and_fit(live_options(args), fit_options(args), args.space)
    if report is not None:
        _print(report, args.json, flight)
    return code


def fly_and_fit(options, fit: FitOptions, space: float):
    """Fly the manoeuvre (within ``space`` m) through run's live loop with ``options`` (a
    FlightOptions), then fit its log: (exit code, report or None when stopped before the
    manoeuvre ended, the flight's summary)."""
    from ..app.flight import Flight, logger, refuse_user_error
    from ..app.options import LogOptions
    from ..ident.excite import Excitation, manoeuvre
    from ..live.params import read_values

    if fit.check:
        from ..ident.data import read_series
        read_series(fit.check)           # a bad check log is refused before anything flies
    log = logger("companion identify", options.output.quiet)
    read: dict[str, float] = {}
    made: list[Excitation] = []

    def make_tracker(link, limits):
        """Read the autopilot's limits (the priors), size the manoeuvre, build the tracker (the
        autopilot's profile says which parameters, and which manoeuvre)."""
        profile = link.vehicle.profile
        read.update(read_values(link, profile.ident.params))
        log(f"{profile.ident.params_label} parameters: "
            + (", ".join(f"{k} {v:g}" for k, v in sorted(read.items()))
               or "none answered; default priors"))
        priors = profile.priors_from(read)
        if priors.steering is not None:
            log(f"steering: {priors.steering.label}")
        made.append(manoeuvre(profile, priors.params, space, limits, priors.steering))
        log(made[-1].describe())
        return made[-1]

    scratch = None
    if not options.log.enabled:      # --no-log: the logs go to a scratch dir, then away
        scratch = tempfile.TemporaryDirectory(prefix="identify-")
        options = replace(options, log=LogOptions(enabled=True, folder=scratch.name))
    try:
        with Flight(options, "identify", log) as flight:
            result = flight.fly(_mission(space), make_tracker=make_tracker)
            refuse_user_error(result)
            paths = flight.paths
            assert paths is not None   # the log is on: the user's or the scratch one
            tracker = made[-1] if made else None
            flight_summary = {
                "reason": result.reason, "exit_code": result.exit_code,
                "hold_confirmed": result.hold_confirmed, "duration_s": result.duration_s,
                "failsafes": result.failsafes, "space_m": space,
                "max_distance_m": tracker.max_distance if tracker else 0.0,
                "returns": tracker.returns if tracker else 0,
                "tlog": None if scratch else paths.tlog, "csv": None if scratch else paths.csv}
            stopped_by = _stopped_by(flight.interrupted, result.reason)
            if stopped_by is not None:
                log(f"stopped by {stopped_by} before the manoeuvre ended: not fitted"
                    + ("" if scratch else f" (the log is {paths.tlog})"))
                return result.exit_code, None, flight_summary
            flight.close_logs()          # the CSV complete before anything reads the logs
            try:
                report = identify_log(paths.tlog, fit, read, log,
                                      "the manoeuvre flown (--no-log: log not kept)" if scratch
                                      else None)
            except UserError as exc:
                if result.exit_code == ExitCode.OK:
                    raise
                # the true reason first: a log cut short by a takeover or a failsafe
                raise UserError(f"the manoeuvre ended early ({result.reason}): {exc}",
                                result.exit_code) from None
    finally:
        if scratch is not None:
            scratch.cleanup()
    return result.exit_code, report, flight_summary
