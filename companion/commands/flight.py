"""One flight, assembled once: what every flying command (run, demo, identify, calibrate) does
around the live loop.

:class:`Flight` owns a flight's lifecycle: SIGTERM / SIGINT turned into a stop request, the
Zenoh bus, the flight-log sinks (the .tlog and the .csv), and their closing on every path out;
the loop itself stops the rover (zero setpoint, then HOLD) however it ends. A command builds its
:class:`~companion.commands.options.FlightOptions`, what is known of its vehicle
(:func:`known_vehicle`), and then, in a few lines::

    with Flight(options, "run", log) as flight:
        result = flight.fly(mission, vehicle)
"""

from __future__ import annotations

import json
import signal
import sys
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core import controllers
from ..errors import UserError
from .options import FlightOptions, LogOptions

if TYPE_CHECKING:   # for the hints only: the bus and the logs load when a flight opens them
    from ..bus import Bus
    from ..live.flightlog import LogPaths

Log = Callable[[str], None]


def logger(prefix: str, quiet: bool) -> Log:
    if quiet:
        return lambda text: None

    def log(text: str) -> None:
        print(f"{prefix}: {text}", file=sys.stderr, flush=True)
    return log


def print_warnings(mission, prog: str = "companion mission") -> None:
    for line in mission.warnings:
        print(f"{prog}: warning: {line}", file=sys.stderr)


def load_mission(path: str, origin_text: str | None, command: str = "companion run"):
    """The mission file read and checked before connecting (a bad one fails early); one
    placed by latitude / longitude is placed again around the vehicle's EKF origin once it is
    known (companion.live.origin)."""
    from .. import mission as missions
    from .arguments import parse_origin
    mission = missions.load(path, origin=parse_origin(origin_text))
    print_warnings(mission, command)
    return mission


def signing_key(path: str | None) -> bytes | None:
    if path is None:
        return None
    from ..mav.signing import load_key
    return load_key(path)


def tune_search(path, **search) -> dict[str, Any]:
    """The robust tuner's settings for the vehicle file ``path``: its autopilot's and steering
    kind's (companion.profiles.tune_settings), then ``search`` (population, rounds, ...) over
    them. Every tune of a vehicle file goes through here: tune, calibrate, run and the rest."""
    from ..profiles import tune_settings
    from ..sim import vehicle_file
    return {**tune_settings(vehicle_file.load(path).params), **search}


def gains_for_vehicle(path, rate: float, command: str, show_bar: bool, log: Log, pool=None,
                      **search):
    """The gains tuned for a vehicle file (found beside it, else tuned now and stored there,
    with a progress bar; ``pool``: robust.pool.worker_pool's): for run, demo, simulate and
    calibrate."""
    from ..progress import progress_bar
    from ..sim.vehicle_gains import gains_for
    with progress_bar(f"tuning for {Path(path).name}", show_bar) as progress:
        return gains_for(path, rate, command, progress, log, pool,
                         **tune_search(path, **search))


def known_vehicle(path: str | None, mission: Any, gains: Any, command: str, show_bar: bool,
                  log: Log, controller: str = controllers.DEFAULT):
    """What the policy knows of the vehicle file ``path`` (None: the mission's [vehicle] file):
    its limits, and its gains for the rate asked, unless a --gains file overrides them or the
    ``controller`` flies gains of its own (then nothing is tuned)."""
    from ..live.policy import KnownVehicle, requested_rate
    path = path or mission.vehicle_file
    if path is None:
        return KnownVehicle()
    from ..sim import vehicle_file
    from ..sim.vehicle_gains import vehicle_limits
    params = vehicle_file.load(path).params
    limits = vehicle_limits(params)
    if gains.gains_file or not controllers.get(controller).uses_pzc_gains:
        return KnownVehicle(limits=limits, w_c=float(params.w_c), d_cen=float(params.d_cen))
    tuned = gains_for_vehicle(path, requested_rate(mission, gains),
                              f"{command} --vehicle {path} (tuned on first use)", show_bar, log)
    return KnownVehicle(gains=tuned, limits=limits, w_c=float(params.w_c),
                        d_cen=float(params.d_cen))


def install_signals(switch) -> Callable[[], None]:
    """SIGTERM and SIGINT stop the rover and end the run; returns a function that undoes it."""
    def handler(signum, frame):
        switch.trigger(signal.Signals(signum).name)

    old = {sig: signal.signal(sig, handler) for sig in (signal.SIGTERM, signal.SIGINT)}

    def restore() -> None:
        for sig, h in old.items():
            signal.signal(sig, h)
    return restore


def open_flight_log(options: LogOptions, label: str,
                    log: Log) -> tuple[LogPaths | None, list[Any]]:
    """(paths or None, [CSV sink]) for ``--log-dir`` / ``--no-log``; the paths are logged."""
    if not options.enabled:
        return None, []
    from ..live.flightlog import new_paths, open_csv
    paths = new_paths(options.folder, label, options.format)
    if paths.mcap is not None:        # --log-format mcap
        from ..live.mcaplog import open_mcap
        sink: Any = open_mcap(paths.mcap)
    else:
        assert paths.csv is not None  # new_paths gives one of the two
        sink = open_csv(paths.csv)
    log(f"flight log: {paths.tlog} and {paths.mcap or paths.csv}")
    return paths, [sink]


class Flight:
    """A flight's lifecycle (a context manager): signals, Zenoh, flight logs, closing.

    On entry the signals are caught (before the loop a signal interrupts the set-up, in the
    loop it stops the rover and ends the run), the bus opens, then the flight log (once every
    flag has been checked: a bad one leaves no empty log). On exit, however the flight ended,
    the bus is shut, the signals restored and the logs closed.
    """

    def __init__(self, options: FlightOptions, label: str, log: Log):
        self.options, self.label, self.log = options, label, log
        self.key = signing_key(options.signing_key_file)   # a bad key fails before anything
        self.paths: LogPaths | None = None
        self.log_sinks: list[Any] = []
        self.bus: Bus | None = None
        self._restore: Callable[[], None] | None = None
        from ..live.session import StopSwitch
        self.switch = StopSwitch()

    def __enter__(self) -> Flight:
        from ..bus import open_bus
        self._restore = install_signals(self.switch)
        try:
            self.bus = open_bus(self.options.bus, self.log)
            self.paths, self.log_sinks = open_flight_log(self.options.log, self.label, self.log)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc_info) -> None:
        from ..bus import shut
        shut(self.bus)
        self.bus = None
        if self._restore is not None:
            self._restore()
            self._restore = None
        self.close_logs()

    def close_logs(self) -> None:
        """Close the flight-log sinks (idempotent: the loop closes them when it ends)."""
        for sink in self.log_sinks:
            sink.close()

    @property
    def interrupted(self) -> str | None:
        """The signal that stopped the flight, or None."""
        return self.switch.reason

    def settings(self, mission: Any, vehicle: Any = None):
        """The live session's settings for ``mission`` on ``vehicle`` (a KnownVehicle)."""
        from ..live.policy import KnownVehicle
        from ..live.session import RunSettings
        o = self.options
        link = replace(o.link, signing_key=self.key,
                       tlog=self.paths.tlog if self.paths is not None else None)
        return RunSettings(link=link, mission=mission, runner=o.runner, gains=o.gains,
                           vehicle=vehicle if vehicle is not None else KnownVehicle(),
                           origin=o.origin, realtime=o.realtime, controller=o.controller,
                           gcs_report=o.gcs_report, handover=o.handover)

    def fly(self, mission: Any, vehicle: Any = None, sinks: Sequence[Any] = (),
            make_tracker: Callable[[Any, Any], Any] | None = None):
        """Fly ``mission``: the RunResult. ``sinks`` besides the flight log and the bus."""
        from ..live.session import fly
        from ..progress import ProgressSink
        all_sinks = list(self.log_sinks) + list(sinks)
        if self.options.output.progress:
            all_sinks.append(ProgressSink(mission.duration, mission.name))
        if self.bus is not None:
            all_sinks.append(self.bus)
        result = fly(self.settings(mission, vehicle), sinks=all_sinks, log=self.log,
                     switch=self.switch, control=self.bus.control if self.bus else None,
                     make_tracker=make_tracker)
        if self.paths is not None:
            write_record(self.paths, result, self.options.vehicle_file)
        return result


RECORD_SCHEMA = "pzc-rover/flight-record/1"


def write_record(paths: Any, result: Any, vehicle_file: str | None) -> None:
    """``<log>.json`` beside the flight log: the command line, the vehicle file (its text) and
    the result (gains, limits, metrics) -- what ``companion report`` shows. A run killed
    before it ends has none; the report then says so."""
    from pathlib import Path
    vehicle_text = None
    if vehicle_file:
        try:
            vehicle_text = Path(vehicle_file).read_text(encoding="utf-8", errors="replace")
        except OSError:
            vehicle_text = None
    record = {"schema": RECORD_SCHEMA, "command": sys.argv, "vehicle_file": vehicle_file,
              "vehicle": vehicle_text, "tlog": paths.tlog, "csv": paths.csv, "mcap": paths.mcap,
              "result": result.as_dict()}
    try:
        Path(paths.tlog).with_suffix(".json").write_text(
            json.dumps(record, indent=1, default=str) + "\n", encoding="utf-8")
    except (OSError, ValueError):
        pass        # the record is a convenience: the flight and its logs stand without it


def refuse_user_error(result) -> None:
    """A run that ended on a user's problem (exit 2: nothing moved) is reported as one line."""
    from ..errors import ExitCode
    if result.exit_code == ExitCode.USER_ERROR:
        raise UserError(result.reason)


def fly_mission(options, mission, label: str = "run", command: str = "companion run"):
    """Fly ``mission`` with ``options`` (a FlightOptions): (the result, the flight log's paths
    or None). Also ``calibrate``'s refining flight. A user's problem raises UserError."""
    log = logger(f"companion {label}", options.output.quiet)
    flight = Flight(options, label, log)          # a bad signing key fails here
    vehicle = known_vehicle(options.vehicle_file, mission, options.gains, command,
                            not options.output.quiet, log,
                            options.controller)   # may tune for a minute
    with flight:
        result = flight.fly(mission, vehicle)
    refuse_user_error(result)
    return result, flight.paths
