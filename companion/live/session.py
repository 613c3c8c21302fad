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

import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

from ..core import controllers
from ..core.limits import Limits
from ..errors import UserError
from . import gcs, policy
from . import handover as handover_mod
from . import origin as origin_mod
from .config import LinkConfig, OriginConfig, RunnerConfig
from .events import ControlChannel, Sink
from .policy import GainOptions, KnownVehicle
from .runner import Runner, stop_cause
from .runner.core import status_fields
from .setup_answers import SETTING_UP, SetupAnswers
from .stats import RunResult


@dataclass(frozen=True)
class RunSettings:
    """Everything a session needs, built once per flight (``companion.commands.flight``)."""

    link: LinkConfig
    mission: Any                       # companion.mission.Mission
    runner: RunnerConfig = RunnerConfig()
    gains: GainOptions = GainOptions()     # what the flags ask (the policy's input)
    vehicle: KnownVehicle = KnownVehicle()  # its vehicle file's gains and limits, if any
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


def fly(s: RunSettings, sinks: Sequence[Sink] = (), control: ControlChannel | None = None,
        log: Callable[[str], None] = lambda text: None,
        switch: StopSwitch | None = None,
        make_tracker: Callable[[Any, Limits], Any] | None = None) -> RunResult:
    """Run one session against a live vehicle; raises UserError for a user's problem.

    ``make_tracker(link, limits)``, if given, builds the tracker instead of the PZC tracker
    (``companion identify`` flies its excitation manoeuvre so); it runs once the vehicle is
    known and its telemetry rate agreed, and may read from the link (parameters) meanwhile.
    """
    from .link import Link

    wall0 = time.perf_counter()
    vehicle_warning: str | None = None
    policy.check_controller(s.controller, s.gains)
    # Before anything connects: a bad --gains file or limit is a user error.
    asked = policy.resolve(s.mission, s.gains, s.vehicle)
    rate, limits = asked.rate, asked.limits
    link = Link(s.link)
    link.log = log
    switch = switch or StopSwitch()
    stop = (lambda: switch.reason is not None)

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
            answers.step = "waiting for the vehicle's heartbeat"
            vehicle = link.wait_vehicle(stop)
            log(f"{vehicle.autopilot} vehicle, system {vehicle.sysid} component {vehicle.compid}, "
                f"mode {link.mode}, {'armed' if link.armed else 'disarmed'}")
            for name in (vehicle.profile.track_mode, vehicle.profile.hold_mode):
                if name not in link.mode_names():
                    raise UserError(f"the vehicle reports no {name} mode "
                                    f"(MAV_TYPE {vehicle.mav_type})")
            mission, origin = s.mission, None
            if mission.geodetic:
                # Placed by latitude / longitude: around the vehicle's own EKF origin, which its
                # LOCAL_POSITION_NED is relative to (not the plan's home, nor a guess).
                answers.step = "reading the vehicle's EKF origin"
                mission, origin = origin_mod.place(mission, link, s.origin.expected,
                                                   s.origin.timeout, log, stop)
            answers.step = "negotiating the telemetry rate"
            accepted, notes = link.negotiate_rate(rate)
            for note in notes:
                log(note)
            log(f"telemetry at {accepted:g} Hz" if accepted else "telemetry rate not confirmed")
            watch_estimate(link, vehicle.profile.estimate, log)
            known, preset = s.vehicle, None
            if make_tracker is None and policy.wants_preset(mission, s.gains, s.vehicle):
                # no vehicle file, no gains: the bundled vehicle it is, or a warning (presets.py)
                answers.step = "reading the parameters a bundled vehicle is known by"
                from .params import read_values
                from .presets import recognise
                found = recognise(link, accepted or rate,
                                  f"companion calibrate --connect {s.link.url} --out DIR --arm",
                                  read_values)
                log(found.note)
                known, preset = found.vehicle, found.preset
                if preset is not None:
                    limits = policy.choose_limits(mission, s.gains, known)
                else:
                    vehicle_warning = found.note
            answers.step = "building the controller"
            limits_text = (f"limits: speed {limits.max_speed:g} m/s, "
                           f"yaw rate {limits.max_yaw_rate:g} rad/s")
            choice = policy.choose_gains(mission, s.gains, known, accepted or rate)
            if make_tracker is None:
                tracker, gains, gains_source = policy.build_tracker(s.controller, choice, limits,
                                                                    s.gains.controller_gains)
                log(f"controller {tracker.name}; gains: {gains_source}; {limits_text}")
            else:
                gains, gains_source = policy.gains_dict(choice.filter, choice.pzc), choice.source
                log(f"gains: {gains_source}; {limits_text}")
                tracker = make_tracker(link, limits)
            config = replace(s.runner, period=1.0 / accepted if accepted else None)
            reporter, commands = gcs.attach(link) if s.gcs_report else (None, None)
            sinks = [*sinks, reporter] if reporter is not None else sinks
            latlon = origin.latlon if origin is not None else None
            handover = (None if s.handover is None
                        else handover_mod.attach(s.handover, link, latlon, log))
            runner = Runner(link, tracker, mission, config, limits, sinks, control, log,
                            origin=latlon, gcs=commands, handover=handover)
            if reporter is not None:
                reporter.watch(runner.status)
            # Sinks that write files (the flight-log CSV) flush when the loop is about to sleep.
            link.on_idle.extend(idle for sink in sinks if (idle := getattr(sink, "idle", None)))
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
    st, t = runner.stats, runner.telemetry
    lat = st.latency
    return RunResult(
        reason=outcome.reason, exit_code=outcome.exit_code,
        f_cost=st.f_cost, steady_rms=st.steady_rms,
        setpoints_sent=link.setpoints_sent, telemetry_received=t.received,
        telemetry_rejected=dict(t.rejected), cycles=st.cycles, loop_rate_hz=st.loop_rate_hz,
        latency_p50_ms=lat.percentile(50) * 1e3, latency_p99_ms=lat.percentile(99) * 1e3,
        latency_max_ms=lat.max_s * 1e3 if lat.n else math.nan,
        missed_cycles=st.gaps + st.overruns, overruns=st.overruns,
        duration_s=runner.mission_time, wall_s=time.perf_counter() - wall0,
        rate_requested_hz=rate, rate_accepted_hz=accepted,
        autopilot=vehicle.autopilot, sysid=vehicle.sysid,
        gains=gains, gains_source=gains_source,
        limits=policy.limits_dict(limits),
        failsafes=outcome.failsafes, hold_confirmed=outcome.hold_confirmed,
        mission=runner.mission.name,
        extra={"controller": tracker.name, "stop_cause": stop_cause(outcome.exit_code),
               **({"vehicle_preset": preset} if preset is not None else {}),
               **({"vehicle_warning": vehicle_warning} if vehicle_warning else {}),
               **({"ekf_origin": origin.as_dict()} if origin is not None else {}),
               "missed_gaps": st.gaps, "backlog": st.backlog,
               "sink_errors": runner.sink_errors, "signing_rejected": link.signing_rejected,
               "tracker_resets": runner.tracker_resets, "stalls": runner.stalls,
               "udp_recv_buffer": link.recv_buffer,
               "tcp_reconnects": link.reconnects,
               **({"handovers": [r.as_dict() for r in handover.results]}
                  if handover is not None else {})})
