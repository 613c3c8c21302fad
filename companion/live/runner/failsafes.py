"""Failsafes: losing the vehicle, getting it back, and who took it out of the track mode.

The timers judge silence (no valid sample for ``stale_timeout``, no heartbeat for
``heartbeat_lost``; not while the companion itself was descheduled and its backlog is unread)
and retry the HOLD. A FAILSAFE stops the rover (zero setpoint, HOLD) and names its cause:
telemetry, heartbeat, estimate, gnss (a drop in the receiver's class the profile's policy holds
for: :mod:`companion.live.gnss_watch`), link, setpoints, or the autopilot's own failsafe, which
is never overridden. A mode the companion did not choose is judged by
:meth:`companion.live.health.FailsafeWatch.who_left`: the autopilot's failsafe, a pilot, or
PX4's offboard loss. Recovery re-engages with the filter and integrators reset; after
``--lost-timeout`` the run ends, naming what kept it there.
"""

from __future__ import annotations

import math
import time
from typing import Any

from ...errors import ExitCode
from ...profiles import gnss
from .. import events as ev
from .. import health
from ..loop_state import ACTIVE, State
from .core import nonzero
from .ending import REBOOTED
from .engaging import Engaging

TIMER_EVERY = 0.02     # wall s: timers run at least this often even while messages pour in


class Failsafes(Engaging):
    """The timers, the failsafe and its recovery, and the judgement of a mode we did not choose."""

    # --- timers -----------------------------------------------------------------------------
    def _timers(self, now: float) -> None:
        self.timers.next_timer = now + TIMER_EVERY
        cfg, state = self.config, self.state
        if now >= self.timers.next_heartbeat:
            self.link.send_heartbeat()
            self.timers.next_heartbeat = now + 1.0
        if state is State.WAITING:
            if now - self.timers.started > cfg.telemetry_timeout:
                t = self.telemetry
                detail = (f" ({t.received} LOCAL_POSITION_NED refused: "
                          f"{nonzero(t.rejected)})" if t.received else "")
                # Nothing moved yet: a user's problem (wrong port, sysid, stream), exit 2.
                self._finish(f"no valid pose telemetry within {cfg.telemetry_timeout:g} s"
                             f"{detail}", ExitCode.USER_ERROR, hold=False)
        elif state is State.FAILSAFE:
            if not self._heartbeat_fresh(now) and not self.heard.heartbeat_lost_said:
                self.heard.heartbeat_lost_said = True
                self.log(f"no vehicle heartbeat for {cfg.heartbeat_lost:g} s")
            if self.telemetry.backwards_streak >= 3:
                self._finish(REBOOTED, ExitCode.VEHICLE_RESTARTED)
            elif now - self.stopping.failsafe_since > cfg.lost_timeout:
                self._give_up(now)
            elif self.stopping.cause == "autopilot":
                pass   # the autopilot's failsafe has the vehicle: no mode request of ours
            elif now >= self.mode_request.next_try and not self.stopping.hold_confirmed:
                self.link.send_stop()
                self._request_mode(self.hold_mode, now)
        elif state in ACTIVE:
            if now < self.heard.catch_up_until:
                pass    # the companion itself was not running: what came meanwhile is unread
            elif now - self.heard.sample_wall > cfg.stale_timeout:
                self._failsafe(now)
            elif not self._heartbeat_fresh(now):
                self.heard.heartbeat_lost_said = True
                self._failsafe(now, f"heartbeat lost: none from the vehicle for "
                                    f"{now - self.heard.heartbeat_wall:.2f} s")
            elif state is State.ENGAGING:
                self._engage(now)

    def _stalled(self, gap: float, now: float) -> None:
        """The loop did not turn for ``gap`` wall s: the process was not scheduled (or a
        handler blocked). The vehicle's silence is judged once its backlog has been read, not
        before: at the socket's head may be an ATTITUDE with the pose samples behind it."""
        self.counters.stalls += 1
        self.heard.catch_up_until = now + self.config.stale_timeout
        if now >= self.timers.next_stall_log:
            self.timers.next_stall_log = now + 10.0
            self.log(f"the companion was not running for {gap:.2f} s (the board is overloaded?): "
                     f"reading what the vehicle sent meanwhile before judging its silence "
                     f"({self.counters.stalls} such stalls so far)")

    def _failsafe(self, now: float, reason: str | None = None, cause: str = "telemetry",
                  hold: bool = True) -> None:
        if reason is None:
            gap = now - self.heard.sample_wall
            reason = f"telemetry stale: no valid sample for {gap:.2f} s"
        stopping = self.stopping
        stopping.cause = cause
        self.clock.rejoin = True
        if hold:
            self.log(f"{reason}; stopping the rover (zero setpoint, {self.hold_mode})")
            self.link.send_stop()
            stopping.hold_confirmed = False
            self._request_mode(self.hold_mode, now)
        else:
            self.log(f"{reason}; no setpoint, no mode request until it clears")
        stopping.resume_to = (self.state if self.state is not State.ENGAGING
                              else self.engagement.after)
        self.state = State.FAILSAFE
        stopping.failsafe_since = now
        self.counters.failsafes += 1
        self._emit(ev.FAILSAFE, reason, {"rejected": dict(self.telemetry.rejected),
                                         "cause": cause, "stop": hold})

    def _recover(self) -> None:
        """Telemetry is back (and the estimate healthy, the autopilot's failsafe cleared):
        forget the filter and integrators, re-engage, then carry on."""
        self.tracker.reset()
        stopping = self.stopping
        out = time.perf_counter() - stopping.failsafe_since
        what = {"estimate": "estimate healthy again", "autopilot": "autopilot failsafe cleared",
                "gnss": f"GNSS back to the run's {gnss.name(self.gnss.start_fix or 0)}",
                "link": "link back", "setpoints": "the vehicle answers the companion again"
                }.get(stopping.cause, "telemetry back")
        self.log(f"{what} after {out:.2f} s; "
                 f"re-engaging {self.track_mode} with the filter and integrators reset")
        need_ack = not stopping.hold_confirmed and stopping.cause != "autopilot"
        self._enter_engaging(stopping.resume_to)
        self.engagement.need_ack = need_ack
        self.engagement.after_failsafe = True
        stopping.autopilot = None
        self.estimate.forget_position()
        self._emit(ev.RESUMED, what, {"cause": stopping.cause})

    def _may_recover(self, now: float) -> bool:
        """In FAILSAFE: the vehicle may be taken back now (heartbeat fresh, estimate healthy,
        no autopilot failsafe holding it unless --retake-after-failsafe and it cleared)."""
        if not self._heartbeat_fresh(now) or not self.estimate.healthy(now):
            return False
        if self.gnss.verdict(now)[0] == gnss.HOLD:
            return False
        if self.stopping.cause == "gnss" and not (self.gnss.back(now) and (
                self.gnss.jump.steering()
                or math.hypot(*self.heard.velocity) < self.gnss.policy.rest_speed)):
            # back for back_for, and either steering by the receiver until the estimate agrees
            # or (no relation to the receiver known yet) the estimate settled: the held rover
            # at rest in it
            return False
        if self.stopping.cause == "setpoints" and not self.stopping.hold_confirmed:
            return False   # until the vehicle has our HOLD: our messages reach it again
        if self.stopping.autopilot is not None:
            return self.config.retake_after_failsafe and self.autopilot_fs.cleared(now)
        active = self.autopilot_fs.active(now)
        if active is None or active[0] in self.profile.failsafe.link_causes:
            return True
        # the critical status that comes with the autopilot's answer to our silence
        return self.stopping.cause == "link" and active[1] == "system_status critical"

    def _on_estimate(self, msg: Any, now: float) -> None:
        """The estimator's report (EKF_STATUS_REPORT / ESTIMATOR_STATUS, the profile's)."""
        if not self.link.is_vehicle(msg):
            return
        facts = self.profile.estimate
        ratios = {name: float(value) for name in facts.variances
                  if (value := getattr(msg, name, None)) is not None}
        self.estimate.report(int(getattr(msg, facts.flags_field)), ratios, now)
        problem = self.estimate.problem(now)
        if problem is None:
            return
        if self.state is State.TRACKING or (self.state is State.ENGAGING
                                            and not self.config.wait_for_mode
                                            and not self.engagement.first(self.state)):
            self._bad_estimate(problem, now)
        # Engaging the first time, and --start-on-guided / --handover before it is engaged:
        # not yet the companion's vehicle to stop; _engage waits for a healthy estimate

    def _on_gnss(self, msg: Any, now: float) -> None:
        """The receiver's report (GPS_RAW_INT): the profile's policy for its class
        (companion.profiles.gnss): carry on, slow the reference, or hold on the path."""
        news = self.gnss.report(msg.fix_type, getattr(msg, "h_acc", 0), now)
        if news is not None:
            self.log(news)
        jumped = self.gnss.jump.fix(msg.lat, msg.lon, self.gnss.h_acc)
        if jumped is not None and self.state is State.TRACKING:
            self.log(jumped)
            self._emit(ev.GNSS, "jump: riding through" if "jumped" in jumped else "jump over",
                       self.gnss.status())
        act, why = self.gnss.verdict(now)
        rate = self.gnss.policy.slow_factor if act == gnss.SLOW else 1.0
        if rate != self.clock.rate:
            self._pace(rate, why)
        if act == gnss.HOLD and (self.state is State.TRACKING or (
                self.state is State.ENGAGING and not self.engagement.first(self.state))):
            self.gnss.noted(act, now)
            self._failsafe(now, f"{why}: holding on the path until it is back for "
                                f"{self.gnss.policy.back_for:g} s", cause="gnss")

    def _pace(self, rate: float, why: str) -> None:
        """The reference runs at ``rate`` times its speed from the last tracked sample on."""
        clock = self.clock
        if clock.segment_t0 is not None:
            clock.offset, clock.segment_t0 = clock.time, self.heard.vehicle_t
        clock.rate, clock.ramp_s = rate, 0.0
        if rate < 1.0:
            self.gnss.noted(gnss.SLOW, self.heard.vehicle_t)
            self._emit(ev.GNSS, f"{self.gnss.short()}: slow", self.gnss.status())
            self.log(f"{why}: the reference slowed to {rate:.0%} of its speed")
        else:
            self.log("GNSS back to the run's class: the reference at full speed again")

    def _bad_estimate(self, problem: str, now: float, time_boot_ms: int = 0) -> None:
        """The position estimate is unfit to steer by: pause (or end, --on-bad-estimate)."""
        if self.config.on_bad_estimate == "end":
            self._emit(ev.FAILSAFE, f"estimate unhealthy: {problem}", {"cause": "estimate"})
            self._finish(f"estimate_unhealthy: {problem}", ExitCode.ESTIMATE_UNHEALTHY,
                         time_boot_ms)
            return
        self._failsafe(now, f"estimate unhealthy: {problem}", cause="estimate")

    def _left(self, mode: str, now: float, stalled: bool) -> None:
        """The vehicle is out of the track mode, in ``mode``: whose doing was it?"""
        in_failsafe, stopping = self.state is State.FAILSAFE, self.stopping
        who, why = self.autopilot_fs.who_left(mode, self.hold_mode, now, stalled,
                                           hold_asked=in_failsafe)
        if in_failsafe and stopping.cause == "autopilot":
            if who != health.AUTOPILOT and mode != self.hold_mode:
                # Cleared, and the vehicle stays in the mode its failsafe (or a pilot) chose.
                self._finish(f"autopilot_failsafe: {stopping.autopilot}; the vehicle stays in "
                             f"{mode}: not taking it back", ExitCode.AUTOPILOT_FAILSAFE,
                             hold=False, stop=False)
        elif who == health.AUTOPILOT and in_failsafe and mode == self.hold_mode \
                and stopping.hold_confirmed:
            # Our own HOLD was in place before the autopilot's failsafe began; still its
            # failsafe: not resumed on our own (--retake-after-failsafe: once it clears).
            cause, evidence = self.autopilot_fs.active(now) or ("own", "")
            self._autopilot_took(f"the autopilot's {cause} failsafe ({evidence}) began while "
                                 f"the rover stood in the companion's {mode} "
                                 f"({stopping.cause} failsafe)", now)
        elif who == health.AUTOPILOT:
            self._autopilot_took(why, now)
        elif who == health.PILOT:
            self._override(why)
        elif in_failsafe:
            if mode == self.hold_mode:
                stopping.hold_confirmed = True
            if who == health.LINK:
                stopping.cause = "link"    # PX4's offboard loss: its status turns critical
        elif who == health.LINK:
            # PX4 left OFFBOARD on its setpoint-loss timeout while telemetry still flowed (our
            # setpoints did not arrive): stop as for our own silence, take it back once back.
            self._failsafe(now, why, cause="link")

    def _chosen_before_engaged(self, mode: str, now: float) -> None:
        """Before the companion engaged, someone else chose ``mode`` (a pilot's switch, a
        ground station, the autopilot's own failsafe): the vehicle was never ours, so it is not
        taken, as a pilot's takeover or the autopilot's failsafe mid-mission is not taken back."""
        who, why = self.autopilot_fs.who_left(mode, self.hold_mode, now,
                                              companion_stalled=False, hold_asked=False)
        why = f"{why} before the companion engaged"
        if who == health.AUTOPILOT:
            self._autopilot_took(why, now)
        else:
            self._override(why)

    def _autopilot_took(self, why: str, now: float) -> None:
        """The autopilot's own failsafe has the vehicle: never taken back on our own (nor
        taken at all, --retake-after-failsafe or not, when it was never ours)."""
        never_ours = self._not_yet_engaged(self.state)
        if not self.config.retake_after_failsafe or never_ours:
            self._end_for_autopilot(why, back=not never_ours)
            return
        if self.stopping.autopilot is None:
            self._emit(ev.AUTOPILOT_FAILSAFE, why)
        if self.state is not State.FAILSAFE:
            self._failsafe(now, f"{why} (--retake-after-failsafe: back once it clears)",
                           cause="autopilot", hold=False)
        self.stopping.cause = "autopilot"
        self.stopping.autopilot = why

    def _give_up(self, now: float) -> None:
        """FAILSAFE for --lost-timeout: end, naming what kept it there."""
        cfg, stopping = self.config, self.stopping
        if stopping.cause == "estimate":
            problem = self.estimate.problem(now) or "not healthy long enough"
            self._finish(f"estimate_unhealthy: for {cfg.lost_timeout:g} s ({problem})",
                         ExitCode.ESTIMATE_UNHEALTHY)
        elif stopping.cause == "autopilot":
            self._finish(f"autopilot_failsafe: {stopping.autopilot} and not cleared within "
                         f"{cfg.lost_timeout:g} s", ExitCode.AUTOPILOT_FAILSAFE, hold=False,
                         stop=False)
        elif stopping.cause == "gnss":
            self._finish(f"estimate_unhealthy: {self.gnss.verdict(now)[1] or 'GNSS below the run'}"
                         f"'s class for {cfg.lost_timeout:g} s", ExitCode.ESTIMATE_UNHEALTHY)
        elif stopping.cause == "setpoints":
            self._finish(f"failsafe: the vehicle did not answer the companion for "
                         f"{cfg.lost_timeout:g} s (its setpoints stopped arriving)",
                         ExitCode.FAULT)
        else:
            self._finish(f"failsafe: telemetry lost for {cfg.lost_timeout:g} s", ExitCode.FAULT)
