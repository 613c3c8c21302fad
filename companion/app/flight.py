"""One flight, assembled once: what every flying command (run, demo, identify, calibrate) does
around the live loop.

:class:`Flight` owns a flight's lifecycle: SIGTERM / SIGINT turned into a stop request, the
Zenoh bus, the flight-log sinks (the .tlog and the .csv), and their closing on every path out;
the loop itself stops the rover (zero setpoint, then HOLD) however it ends. A command builds its
:class:`~companion.app.options.FlightOptions`, loads its vehicle once
(:func:`companion.app.vehicle.for_flight`), works out what the policy knows of it
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
    from ..bus.vehicle import Bus
    from ..live.flightlog import LogPaths
    from ..vehicle import Vehicle

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


def known_vehicle(vehicle: Vehicle | None, mission: Any, gains: Any, command: str,
                  show_bar: bool, log: Log, controller: str = controllers.DEFAULT):
    """What the policy knows of ``vehicle`` (loaded once by the command; None: nothing): its
    limits, and its gains for the rate asked, unless a --gains file overrides them or the
    ``controller`` flies gains of its own (then nothing is tuned)."""
    from ..live.policy import KnownVehicle, requested_rate
    from .vehicle import gains_for, known
    if vehicle is None:
        return KnownVehicle()
    if gains.gains_file or not controllers.get(controller).uses_pzc_gains:
        return known(vehicle)
    tuned = gains_for(vehicle, requested_rate(mission, gains),
                      f"{command} --vehicle {vehicle.path} (tuned on first use)", show_bar, log)
    return known(vehicle, tuned)


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
        from ..bus.vehicle import open_bus
        self._restore = install_signals(self.switch)
        try:
            self.bus = open_bus(self.options.bus, self.log)
            self.paths, self.log_sinks = open_flight_log(self.options.log, self.label, self.log)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc_info) -> None:
        from ..bus.vehicle import shut
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
        from ..live.policy import KnownVehicle, wants_preset
        from ..live.session import RunSettings
        from .vehicle import bundled_all
        o = self.options
        link = replace(o.link, signing_key=self.key,
                       tlog=self.paths.tlog if self.paths is not None else None)
        vehicle = vehicle if vehicle is not None else KnownVehicle()
        return RunSettings(link=link, mission=mission, runner=o.runner, gains=o.gains,
                           vehicle=vehicle,
                           bundled=bundled_all() if wants_preset(mission, o.gains, vehicle)
                           else {},
                           origin=o.origin, realtime=o.realtime, controller=o.controller,
                           gcs_report=o.gcs_report, handover=o.handover)

    def fly(self, mission: Any, vehicle: Any = None, sinks: Sequence[Any] = (),
            make_tracker: Callable[[Any, Any], Any] | None = None,
            loaded: Vehicle | None = None):
        """Fly ``mission``: the RunResult. ``vehicle``: what the policy knows of it (a
        KnownVehicle); ``loaded``: its vehicle file, for the flight record; ``sinks`` besides
        the flight log and the bus."""
        from ..live.coverage import CoverageSink
        from ..live.session import fly
        from ..progress import ProgressSink
        all_sinks = list(self.log_sinks) + list(sinks)
        if self.options.output.progress:
            all_sinks.append(ProgressSink(mission.duration, mission.name))
        if self.bus is not None:
            all_sinks.append(self.bus)
        cover = mission.field_cover()
        covered = CoverageSink(cover, mission.frame) if cover is not None else None
        if covered is not None:
            all_sinks.append(covered)
        result = fly(self.settings(mission, vehicle), sinks=all_sinks, log=self.log,
                     switch=self.switch, control=self.bus.control if self.bus else None,
                     make_tracker=make_tracker)
        if covered is not None:
            result.extra["coverage"] = covered.figures()
        if self.paths is not None:
            write_record(self.paths, result, loaded)
        return result


RECORD_SCHEMA = "pzc-rover/flight-record/1"


def write_record(paths: Any, result: Any, vehicle: Vehicle | None) -> None:
    """``<log>.json`` beside the flight log: the command line, the vehicle file (its path and
    the text it was loaded from) and the result (gains, limits, metrics) -- what ``companion
    report`` shows. A run killed before it ends has none; the report then says so."""
    record = {"schema": RECORD_SCHEMA, "command": sys.argv,
              "vehicle_file": vehicle.path if vehicle is not None else None,
              "vehicle": vehicle.text if vehicle is not None else None, "tlog": paths.tlog,
              "csv": paths.csv, "mcap": paths.mcap, "result": result.as_dict()}
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
    or None). Also ``calibrate``'s refining flight. The vehicle file (``--vehicle``, else the
    mission's) is loaded here, once. A user's problem raises UserError."""
    from .vehicle import for_flight
    log = logger(f"companion {label}", options.output.quiet)
    flight = Flight(options, label, log)          # a bad signing key fails here
    mission, loaded = for_flight(options.vehicle_file, mission)
    vehicle = known_vehicle(loaded, mission, options.gains, command, not options.output.quiet,
                            log, options.controller)   # may tune for a minute
    with flight:
        result = flight.fly(mission, vehicle, loaded=loaded)
    refuse_user_error(result)
    return result, flight.paths
