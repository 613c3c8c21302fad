"""A flight's options, typed, read once from the parsed flags (and the ``--config`` file, which
fills the same flags: :mod:`companion.app.config_file`).

One reader per argument group of :mod:`companion.app.arguments`; a command calls the
readers of the groups it registered, and :meth:`FlightOptions.from_args` reads them all for
``companion run``. What the loop itself needs are the live layer's dataclasses
(:mod:`companion.live.config`, :class:`companion.live.policy.GainOptions`); the rest (flight
logs, output, Zenoh) are the edges' own. Nothing downstream reads ``args``.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field
from typing import Any

from ..core.controllers import DEFAULT as DEFAULT_CONTROLLER
from ..live.config import LinkConfig, OriginConfig, RunnerConfig
from ..live.policy import GainOptions


@dataclass(frozen=True)
class LogOptions:
    """--log-dir / --no-log."""

    enabled: bool = True
    folder: str | None = None          # None: ./logs
    format: str = "csv"                # the loop's log beside the .tlog: "csv" or "mcap"


@dataclass(frozen=True)
class OutputOptions:
    """--json, --progress, -q."""

    json: bool = False
    progress: bool = False
    quiet: bool = False


def _no_bus() -> Any:
    from ..bus.config import BusOptions
    return BusOptions(enabled=False)


@dataclass(frozen=True)
class FlightOptions:
    """Everything a flying command was asked, built once."""

    link: LinkConfig                   # signing_key and tlog are filled when the flight opens
    runner: RunnerConfig = RunnerConfig()
    gains: GainOptions = GainOptions()
    vehicle_file: str | None = None    # --vehicle (else the mission's [vehicle] file)
    controller: str = DEFAULT_CONTROLLER   # --controller (companion.core.controllers)
    origin: OriginConfig = OriginConfig()
    realtime: bool = False
    signing_key_file: str | None = None
    log: LogOptions = LogOptions()
    output: OutputOptions = OutputOptions()
    bus: Any = field(default_factory=_no_bus)   # companion.bus.config.BusOptions
    gcs_report: bool = True            # --no-gcs-report turns it off (companion.live.gcs)
    handover: Any = None               # --handover: a companion.live.handover.HandoverPlan

    def for_handover(self, plan: Any, auto_mode: str) -> FlightOptions:
        """--handover: AUTO's guided sub-mode is the track mode, entered by the mission, never
        asked for; the rover's pose at each hand-over is the segment's start (no start limit)."""
        from dataclasses import replace
        runner = replace(self.runner, wait_for_mode=True, track_mode=auto_mode,
                         autostart=False, max_start_distance=math.inf)
        return replace(self, runner=runner, handover=plan)

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> FlightOptions:
        """``companion run``'s flags: every group."""
        return cls(link=link_config(args),
                   runner=runner_config(args, max_start_distance=start_limit(
                       args.max_start_distance), wait_for_mode=args.start_on_guided),
                   gcs_report=args.gcs_report,
                   gains=gain_options(args), vehicle_file=args.vehicle,
                   controller=args.controller,
                   origin=origin_config(args), realtime=args.realtime,
                   signing_key_file=args.signing_key, log=log_options(args),
                   output=output_options(args), bus=bus_options(args))


# --- one reader per group of companion.app.arguments ------------------------------------

def link_config(args: argparse.Namespace) -> LinkConfig:
    """add_link_arguments + add_timeout_arguments' --heartbeat-timeout."""
    return LinkConfig(url=args.connect, sysid=args.sysid, baud=args.baud,
                      heartbeat_timeout=args.heartbeat_timeout,
                      source_system=getattr(args, "source_system", None))


def runner_config(args: argparse.Namespace, **more: Any) -> RunnerConfig:
    """add_timeout_arguments + --arm (+ add_origin_arguments' --max-start-distance, if given)."""
    return RunnerConfig(arm=args.arm, stale_timeout=args.stale_timeout,
                        telemetry_timeout=args.telemetry_timeout, arm_timeout=args.arm_timeout,
                        lost_timeout=args.lost_timeout, on_bad_estimate=args.on_bad_estimate,
                        estimate_healthy_for=args.estimate_healthy_for,
                        estimate_step=args.estimate_step,
                        estimate_variance=args.estimate_variance,
                        estimate_wait=args.estimate_wait,
                        retake_after_failsafe=args.retake_after_failsafe, **more)


def start_limit(metres: float) -> float:
    """--max-start-distance in metres; 0: no limit."""
    return math.inf if not metres else float(metres)


def origin_config(args: argparse.Namespace) -> OriginConfig:
    """add_origin_arguments (its --max-start-distance goes to the runner)."""
    from .arguments import parse_origin
    return OriginConfig(expected=parse_origin(args.origin), timeout=args.origin_timeout)


def gain_options(args: argparse.Namespace, vehicle: bool = True) -> GainOptions:
    """add_gain_arguments (+ add_vehicle_arguments' --w-c and --d-cen when ``vehicle``)."""
    from .arguments import controller_gains
    return GainOptions(rate=args.rate, gains_file=args.gains, k_df=args.k_df,
                       lambda_f=args.lambda_f, k_dc=args.k_dc, lambda_c=args.lambda_c,
                       max_speed=args.max_speed, max_yaw_rate=args.max_yaw_rate,
                       controller_gains=controller_gains(args.controller, args.controller_gains),
                       w_c=args.w_c if vehicle else None, d_cen=args.d_cen if vehicle else None)


def log_options(args: argparse.Namespace) -> LogOptions:
    """add_safety_arguments' --log-dir / --no-log."""
    return LogOptions(enabled=args.log, folder=args.log_dir,
                      format=getattr(args, "log_format", "csv"))


def output_options(args: argparse.Namespace, progress: bool = True) -> OutputOptions:
    """add_output_arguments (``progress``: the command has --progress)."""
    return OutputOptions(json=args.json, progress=args.progress if progress else False,
                         quiet=args.quiet)


def bus_options(args: argparse.Namespace, mode: str | None = None) -> Any:
    """add_zenoh_arguments: a companion.bus.config.BusOptions."""
    from ..bus.config import BusOptions
    common = dict(mode=mode or args.zenoh_mode, connect=tuple(args.zenoh_connect),
                  listen=tuple(args.zenoh_listen), config_file=args.zenoh_config,
                  scouting=args.zenoh_scouting, tls=args.zenoh_tls,
                  roles=tuple(args.zenoh_roles))
    if not args.zenoh_vehicle:
        return BusOptions(**common)
    return BusOptions(enabled=args.zenoh, vehicle_id=args.vehicle_id,
                      state_every=args.state_every, control_secret=args.control_secret,
                      **common)
