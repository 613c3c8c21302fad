"""One companion session: settings in, RunResult out (what every flying command shares).

Connect, wait for the vehicle, negotiate the telemetry rate, recognise a bundled vehicle when
nothing says what it is (:mod:`companion.live.presets`), resolve gains and limits for the
rate the vehicle actually accepted (:mod:`companion.live.policy`, the one policy), build the
tracker ``--controller`` names (:mod:`companion.core.controllers`: pzc flies the policy's gains,
pid and kanayama their own, ``--controller-gains`` or defaults, all within the policy's
limits), run the loop
(:mod:`companion.live.runner`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from ..core import controllers
from ..core.limits import Limits
from ..errors import UserError
from ..profiles.gnss import GPS_RAW_INT_ID
from . import gcs, policy
from . import handover as handover_mod
from . import origin as origin_mod
from .config import LinkConfig, OriginConfig, RunnerConfig
from .events import ControlChannel, Sink
from .policy import GainOptions, KnownVehicle
from .result import RunResult, result_of
from .runner import Runner
from .runner.core import status_fields
from .setup_answers import SETTING_UP, SetupAnswers


@dataclass(frozen=True)
class RunSettings:
    """Everything a session needs, built once per flight (``companion.app.flight``)."""

    link: LinkConfig
    mission: Any                       # companion.mission.Mission
    runner: RunnerConfig = RunnerConfig()
    gains: GainOptions = GainOptions()     # what the flags ask (the policy's input)
    vehicle: KnownVehicle = KnownVehicle()  # its vehicle file's gains and limits, if any
    bundled: Mapping[str, Any] = field(default_factory=dict)  # the bundled vehicles, loaded
                                       # (companion.vehicle.Vehicle by preset name): what a
                                       # vehicle flown without a file is matched against
    origin: OriginConfig = OriginConfig()
    realtime: bool = False             # --realtime: SCHED_FIFO for the loop
    controller: str = controllers.DEFAULT   # --controller: a name in companion.core.controllers
    gcs_report: bool = True            # STATUSTEXT / NAMED_VALUE_FLOAT / DO_PAUSE_CONTINUE
    handover: Any = None               # --handover: a live.handover.HandoverPlan


REALTIME_PRIORITY = 10   # low among real-time tasks: above every normal process, below the kernel's


def take_realtime(log: Callable[[str], None]) -> bool:
    """SCHED_FIFO for this process, so a busy board does not delay a kHz loop. Best effort:
    without the privilege the loop runs at normal priority and says so."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
    except (AttributeError, OSError) as exc:
        log(f"--realtime: SCHED_FIFO not granted ({exc}); running at normal priority")
        return False
    log(f"--realtime: control loop under SCHED_FIFO priority {REALTIME_PRIORITY}")
    return True


class StopSwitch:
    """What a signal handler calls: before the loop runs it interrupts the set-up, once the
    loop runs it asks the loop to stop the rover and finish."""

    def __init__(self) -> None:
        self.runner: Runner | None = None
        self.reason: str | None = None

    def trigger(self, reason: str) -> None:
        self.reason = reason
        if self.runner is None:
            raise KeyboardInterrupt(reason)
        self.runner.request_stop(reason)


def watch_estimate(link: Any, facts: Any, log: Callable[[str], None]) -> None:
    """Ask for the estimator's report (companion.live.health watches it); one try, so a
    vehicle that does not answer costs one ACK timeout."""
    result = link.command_wait(511, facts.message_id, 1e6 / facts.rate_hz, tries=1)
    if result != 0:   # MAV_CMD_SET_MESSAGE_INTERVAL not accepted
        log(f"{facts.message} at {facts.rate_hz:g} Hz not confirmed (COMMAND_ACK "
            f"{result}): the estimate is watched through what arrives and through "
            "LOCAL_POSITION_NED steps")


def watch_gnss(link: Any, policy: Any, log: Callable[[str], None]) -> None:
    """Ask for GPS_RAW_INT (the receiver's class: companion.live.gnss_watch) at the policy's
    rate; one try. Unconfirmed, the class is judged from what arrives (often the vehicle's
    default stream) or, if nothing does, not at all."""
    result = link.command_wait(511, GPS_RAW_INT_ID, 1e6 / policy.rate_hz, tries=1)
    if result != 0:
        log(f"GPS_RAW_INT at {policy.rate_hz:g} Hz not confirmed (COMMAND_ACK {result}): the "
            "receiver's class is judged from what arrives")


@dataclass
class Connected:
    """What the set-up learnt of the vehicle, before anything is resolved."""

    vehicle: Any                       # link.VehicleInfo: its autopilot, ids, profile
    mission: Any                       # placed around its EKF origin, if by lat / lon
    origin: Any                        # origin.Origin, or None
    accepted: float | None             # the telemetry rate it accepted (None: not confirmed)


@dataclass
class Flown:
    """What the session flies, resolved once: limits, gains, the tracker."""

    limits: Limits
    tracker: Any
    gains: dict[str, Any]              # the gains flown (the result's)
    gains_source: str
    preset: str | None = None          # the bundled vehicle recognised, if any
    warning: str | None = None         # gains not for this vehicle (no preset matched)


def connect(s: RunSettings, link: Any, answers: SetupAnswers, rate: float,
            log: Callable[[str], None], stop: Callable[[], bool]) -> Connected:
    """Wait for the vehicle, check its modes, place a lat / lon mission around its EKF origin,
    agree the telemetry rate and ask for its estimator's report."""
    answers.step = "waiting for the vehicle's heartbeat"
    vehicle = link.wait_vehicle(stop)
    log(f"{vehicle.autopilot} vehicle, system {vehicle.sysid} component {vehicle.compid}, "
        f"mode {link.mode}, {'armed' if link.armed else 'disarmed'}")
    for name in (vehicle.profile.track_mode, vehicle.profile.hold_mode):
        if name not in link.mode_names():
            raise UserError(f"the vehicle reports no {name} mode (MAV_TYPE {vehicle.mav_type})")
    mission, origin = s.mission, None
    if mission.geodetic:
        # Placed by latitude / longitude: around the vehicle's own EKF origin, which its
        # LOCAL_POSITION_NED is relative to (not the plan's home, nor a guess).
        answers.step = "reading the vehicle's EKF origin"
        mission, origin = origin_mod.place(mission, link, s.origin.expected, s.origin.timeout,
                                           log, stop)
    answers.step = "negotiating the telemetry rate"
    accepted, notes = link.negotiate_rate(rate)
    for note in notes:
        log(note)
    log(f"telemetry at {accepted:g} Hz" if accepted else "telemetry rate not confirmed")
    watch_estimate(link, vehicle.profile.estimate, log)
    watch_gnss(link, vehicle.profile.gnss, log)
    return Connected(vehicle, mission, origin, accepted)


def resolve(s: RunSettings, link: Any, found: Connected, rate: float, answers: SetupAnswers,
            log: Callable[[str], None],
            make_tracker: Callable[[Any, Limits], Any] | None) -> Flown:
    """Limits, gains and the tracker, once, for the rate flown: from the settings' vehicle, or
    (nothing saying what it is) the bundled vehicle it matches, or a warning that the gains
    are not for it (:mod:`companion.live.presets`)."""
    known, preset, warning = s.vehicle, None, None
    rate = found.accepted or rate
    if make_tracker is None and policy.wants_preset(found.mission, s.gains, s.vehicle):
        answers.step = "reading the parameters a bundled vehicle is known by"
        from .params import read_values
        from .presets import recognise
        match = recognise(link, rate, f"companion calibrate --connect {s.link.url} --out DIR "
                                      "--arm", read_values, s.bundled)
        log(match.note)
        if match.preset is not None:
            known, preset = match.vehicle, match.preset
        else:
            warning = match.note
    answers.step = "building the controller"
    chosen = policy.resolve(found.mission, s.gains, known, rate)
    limits = chosen.limits
    limits_text = (f"limits: speed {limits.max_speed:g} m/s, "
                   f"yaw rate {limits.max_yaw_rate:g} rad/s")
    if make_tracker is None:
        tracker, gains, source = policy.build_tracker(s.controller, chosen.gains, limits,
                                                      s.gains.controller_gains)
        log(f"controller {tracker.name}; gains: {source}; {limits_text}")
    else:
        gains, source = policy.gains_dict(chosen.gains.filter, chosen.gains.pzc), \
            chosen.gains.source
        log(f"gains: {source}; {limits_text}")
        tracker = make_tracker(link, limits)
    return Flown(limits, tracker, gains, source, preset, warning)


def fly(s: RunSettings, sinks: Sequence[Sink] = (), control: ControlChannel | None = None,
        log: Callable[[str], None] = lambda text: None,
        switch: StopSwitch | None = None,
        make_tracker: Callable[[Any, Limits], Any] | None = None) -> RunResult:
    """Run one session against a live vehicle; raises UserError for a user's problem.

    Set up (connect), resolve once (limits, gains, a bundled vehicle), fly (the loop), and
    the result. ``make_tracker(link, limits)``, if given, builds the tracker instead of the
    PZC tracker (``companion identify`` flies its excitation manoeuvre so); it runs once the
    vehicle is known and its telemetry rate agreed, and may read from the link meanwhile.
    """
    from .link import Link

    wall0 = time.perf_counter()
    rate = policy.check(s.mission, s.gains, s.vehicle, s.controller)   # before connecting
    link = Link(s.link)
    link.log = log
    switch = switch or StopSwitch()

    def setup_status() -> dict[str, Any]:
        """What a ``status`` request gets while the setup runs (the loop's keys)."""
        found = link.found
        track = s.runner.track_mode or (found.profile.track_mode if found else None)
        return status_fields(SETTING_UP, s.mission, track, link.mode if found else None, link)

    def abort() -> None:
        switch.reason = switch.reason or "aborted"

    try:
        # the control channel is answered meanwhile: status, abort; the loop takes it after
        with SetupAnswers(control, setup_status, abort) as answers:
            found = connect(s, link, answers, rate, log, lambda: switch.reason is not None)
            flown = resolve(s, link, found, rate, answers, log, make_tracker)
            runner, reporter, handover = build_runner(s, link, found, flown, sinks, control, log)
        switch.runner = runner
        if switch.reason is not None:        # a signal or an abort during the setup
            runner.request_stop(switch.reason)
        if s.realtime:
            take_realtime(log)
        outcome = runner.run()
        if reporter is not None:
            link.linger(reporter.linger)
    finally:
        link.close()
    extra = {**({"vehicle_preset": flown.preset} if flown.preset is not None else {}),
             **({"vehicle_warning": flown.warning} if flown.warning else {}),
             **({"ekf_origin": found.origin.as_dict()} if found.origin is not None else {}),
             "gnss": runner.gnss.summary(),
             **({"handovers": [r.as_dict() for r in handover.results]}
                if handover is not None else {})}
    return result_of(outcome, runner, link, found.vehicle, flown, rate, found.accepted,
                     time.perf_counter() - wall0, extra)


def build_runner(s: RunSettings, link: Any, found: Connected, flown: Flown,
                 sinks: Sequence[Sink], control: ControlChannel | None,
                 log: Callable[[str], None]) -> tuple[Runner, Any, Any]:
    """The loop, with the ground station's reporter and the hand-over plan if asked: (the
    runner, the reporter or None, the hand-over or None)."""
    config = replace(s.runner, period=1.0 / found.accepted if found.accepted else None)
    reporter, commands = gcs.attach(link) if s.gcs_report else (None, None)
    sinks = [*sinks, reporter] if reporter is not None else sinks
    latlon = found.origin.latlon if found.origin is not None else None
    handover = (None if s.handover is None
                else handover_mod.attach(s.handover, link, latlon, log))
    runner = Runner(link, flown.tracker, found.mission, config, flown.limits, sinks, control,
                    log, origin=latlon, gcs=commands, handover=handover)
    if reporter is not None:
        reporter.watch(runner.status)
    # Sinks that write files (the flight-log CSV) flush when the loop is about to sleep.
    link.on_idle.extend(idle for sink in sinks if (idle := getattr(sink, "idle", None)))
    return runner, reporter, handover
