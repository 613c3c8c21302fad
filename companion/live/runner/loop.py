"""The live control loop: a state machine driven by the vehicle's telemetry.

One thread. Each LOCAL_POSITION_NED that passes :mod:`companion.live.telemetry` is one cycle: while
TRACKING it goes through the tracker (filter + PZC law) against ``trajectory.sample(mission
time)`` and one setpoint goes out; in every other active state the cycle answers with a zero
setpoint (the rover stands still, PX4 keeps its offboard stream, a lockstep plant keeps
stepping). Times come from the vehicle's ``time_boot_ms``: mission time 0 is the first tracking
sample and the clock stands still while paused or in failsafe. The companion's wall clock only
measures silence (stale telemetry), latency and retry intervals.

    WAITING --first valid sample--> ENGAGING --mode (+ armed)--> TRACKING --mission end--> DONE
                                          \\-> READY (no autostart) --start--> TRACKING
    TRACKING <--pause/resume--> PAUSED
    any active state --no valid sample for stale_timeout--> FAILSAFE (zero setpoint, HOLD)
    any active state --no vehicle heartbeat for heartbeat_lost--> FAILSAFE (same)
    FAILSAFE --valid sample and a fresh heartbeat--> ENGAGING (tracker.reset(), back to GUIDED)
             --> previous state
    READY / TRACKING / PAUSED --the vehicle leaves GUIDED / OFFBOARD (a pilot)--> DONE at once:
             no further setpoint, no mode request (never fight the pilot), PILOT_OVERRIDE event
    TRACKING / ENGAGING --the estimate flagged or stepped (companion.live.health)--> FAILSAFE
             (cause "estimate"); back once healthy for --estimate-healthy-for, or DONE
    ENGAGING the first time asks nothing of the vehicle until the estimate is healthy (a
             vehicle just powered on has no position yet); DONE after --estimate-wait
    any state --the autopilot's own failsafe takes the vehicle--> DONE (AUTOPILOT_FAILSAFE: no
             setpoint, no mode request), or FAILSAFE until it clears (--retake-after-failsafe)

Who took the vehicle out of GUIDED / OFFBOARD is :meth:`companion.live.health.FailsafeWatch.
who_left`'s answer (the autopilot's failsafe texts and system_status, the companion's own HOLD),
and each end has its own exit code (:class:`companion.errors.ExitCode`). After a failsafe in
which the companion's HOLD was not seen, a track-mode heartbeat counts only after the vehicle
has answered a mode request (COMMAND_ACK): heartbeats queued during a link stall say GUIDED
from before the stall, and the HOLD queued on our side arrives after them.

It stops the rover itself (zero setpoint, then HOLD) at the mission's end, on a stop request
(SIGTERM / Ctrl-C via :meth:`Runner.request_stop`), on ``abort``, and when it gives up. Every
command is checked right before encoding: a non-finite or out-of-limit one stops the rover.
A gap of more than ``max_gap`` vehicle seconds between two tracked samples (a long dropout, a
burst after a stall) starts a new segment with the filter and integrators reset, so no step
integrates a huge dt; time going back never reaches the tracker (:mod:`companion.live.telemetry`).
Sinks get a LoopRecord per tracking cycle and a StatusEvent per life-cycle change; a
ControlChannel, if given, is polled once per cycle.
"""

from __future__ import annotations

import gc
import json
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ..core.limits import Limits
from ..core.signals import Command, Measurement, Reference
from ..core.trajectory import Trajectory
from ..errors import ExitCode, UserError
from . import events as ev
from . import health
from .config import RunnerConfig, segment_gap
from .events import ControlChannel, ControlRequest, LoopRecord, Sink, StatusEvent
from .link import Link
from .loop_state import (
    ACTIVE,
    Counters,
    Engagement,
    GroundStation,
    Heard,
    MissionClock,
    ModeRequest,
    Outcome,
    State,
    Stopping,
    Timers,
)
from .stats import TrackingStats
from .telemetry import Sample, TelemetryCheck, clock_went_back

_finite = math.isfinite
REBOOTED = ("vehicle_restarted: time_boot_ms went back (the autopilot rebooted); not resuming a "
            "mission on a rebooted vehicle")
# Before a mode change is called a pilot's, the vehicle's clock is read (a rebooted autopilot
# comes back in its boot mode, disarmed, and after a reboot streams nothing it was asked for):
# from its stream for CLOCK_LISTEN wall s, then, if it had fallen silent before the mode
# change (a reboot's gap; never a vehicle a pilot took while it streamed), asked for
# SYSTEM_TIME; CLOCK_WAIT in all.
CLOCK_KINDS = ("SYSTEM_TIME", "ATTITUDE", "LOCAL_POSITION_NED")
CLOCK_LISTEN = 0.5
CLOCK_WAIT = 3.0
TIMER_EVERY = 0.02     # wall s: timers run at least this often even while messages pour in
MAX_WAIT = 0.05        # wall s: the longest sleep (so stop requests are seen promptly)
# wall s between two turns of the loop that only the companion's own stall explains (an
# overloaded board descheduled it): four of its longest sleeps
STALL = 4 * MAX_WAIT
# vehicle s of telemetry the first engagement waits for the estimator's first report (asked for
# at 5 Hz), so a vehicle that has no position yet is not engaged on the strength of no news
FIRST_REPORT_GRACE = 1.0


class Runner:
    def __init__(self, link: Link, tracker: Any, mission: Any, config: RunnerConfig,
                 limits: Limits, sinks: Sequence[Sink] = (), control: ControlChannel | None = None,
                 log: Callable[[str], None] = lambda text: None,
                 origin: tuple[float, float] | None = None, gcs: Any = None,
                 handover: Any = None):
        self.link, self.tracker, self.mission = link, tracker, mission
        self.ground = GroundStation(gcs, handover)
        self.origin = origin              # the vehicle's EKF origin (lat, lon), when known
        self.config, self.limits, self.log = config, limits, log
        self.sinks = list(sinks)
        self.control = control
        v = link.vehicle
        self.profile = v.profile          # the autopilot's: modes, offboard warm-up
        self.telemetry = TelemetryCheck(v.sysid, v.compid, max_attitude_age=config.stale_timeout)
        self.stats = TrackingStats(mission.duration, config.period)
        self.state = State.WAITING
        self.trajectory: Trajectory | None = None   # anchored at the first tracking sample
        self.outcome: Outcome | None = None
        self.heard = Heard()
        self.clock = MissionClock(max_gap=segment_gap(config.max_gap, config.period))
        self.engagement = Engagement(after=State.TRACKING if config.autostart else State.READY,
                                     start_mode=link.mode)
        self.mode_request = ModeRequest()
        self.stopping = Stopping()
        self.timers = Timers()
        self.counters = Counters()
        self.estimate = health.EstimateWatch(
            self.profile.estimate, config.estimate_variance, config.estimate_step,
            config.estimate_healthy_for, max_step_dt=self.clock.max_gap)
        self.autopilot_fs = health.FailsafeWatch(self.profile.failsafe)

    @property
    def track_mode(self) -> str:
        return self.config.track_mode or self.profile.track_mode

    @property
    def hold_mode(self) -> str:
        return self.profile.hold_mode

    @property
    def mission_time(self) -> float:
        return self.clock.time

    @property
    def failsafes(self) -> int:
        return self.counters.failsafes

    @property
    def sink_errors(self) -> int:
        return self.counters.sink_errors

    @property
    def tracker_resets(self) -> int:
        return self.counters.tracker_resets

    @property
    def stalls(self) -> int:
        return self.counters.stalls

    # --- public -----------------------------------------------------------------------------
    def request_stop(self, reason: str) -> None:
        """Ask the loop to stop the rover and end (safe to call from a signal handler)."""
        if self.stopping.requested is None:
            self.stopping.requested = reason

    def run(self) -> Outcome:
        link, clock = self.link, time.perf_counter
        now = clock()
        self.timers.started = self.heard.sample_wall = self.heard.heartbeat_wall = now
        self.heard.loop_wall = now
        self.timers.next_timer = now
        self.timers.next_heartbeat = now
        v = link.vehicle
        self._emit(ev.CONNECTED, f"{v.autopilot} system {v.sysid}",
                   {"autopilot": v.autopilot, "sysid": v.sysid, "compid": v.compid})
        recv, on_position = link.recv, self._on_position
        attitude = self.telemetry.attitude
        # The setup's waits (rate negotiation, parameters, ...) read the streams too: the
        # attitude they heard last is the one the first pose sample goes with. Otherwise a
        # pose read right after its own ATTITUDE was consumed there is refused ("no_attitude"),
        # as a loaded machine made the lockstep plant's first sample (2026-12-04). Its vehicle
        # time is checked as any attitude's: a stale one serves no sample.
        held = link.last_heard("ATTITUDE")
        if held is not None:
            attitude(held)
        # Everything alive now (modules, pymavlink's tables) moves out of the collector's
        # reach, so a full collection during the loop scans only what the loop allocated
        # (measured: ~37 ms for a full collection after the imports, 37 missed cycles at 1 kHz).
        gc.collect()
        gc.freeze()
        try:
            self._loop(recv, on_position, attitude, clock)
        except BaseException as exc:
            # A bug must not leave the rover driving on its last setpoint: stop it, then fail.
            if self.state is not State.DONE:
                self._finish(f"internal error: {type(exc).__name__}: {exc}", ExitCode.FAULT)
                self._wait_for_hold()
            raise
        finally:
            gc.unfreeze()
        if self.stopping.unjudged is not None:
            self._judge_override(self.stopping.unjudged)
        self._wait_for_hold()
        assert self.outcome is not None   # the loop ends only through _finish
        self._emit(ev.STOPPED, self.outcome.reason,
                   {"exit_code": self.outcome.exit_code,
                    "stop_cause": stop_cause(self.outcome.exit_code),
                    "hold_confirmed": self.stopping.hold_confirmed})
        self.outcome.hold_confirmed = self.stopping.hold_confirmed
        for sink in self.sinks:
            self._safely(sink.close)
        return self.outcome

    def _loop(self, recv: Callable[[], Any], on_position: Callable[[Any, float], None],
              attitude: Callable[[Any], None], clock: Callable[[], float]) -> None:
        link = self.link
        estimate_kind = self.profile.estimate.message
        while self.state is not State.DONE:
            if self.stopping.requested is not None:
                self._finish(self.stopping.requested, ExitCode.OK)
                break
            if self.control is not None:
                for request in self.control.poll():
                    self._on_request(request)
                    if not request.ok and self.ground.gcs is not None:
                        self.ground.gcs.refused(f"{request.verb}: {request.message}")
            t_read = clock()
            if t_read - self.heard.loop_wall > STALL:
                self._stalled(t_read - self.heard.loop_wall, t_read)
            self.heard.loop_wall = t_read
            msg = recv()
            if msg is None:
                self.heard.waited = True
                self.heard.catch_up_until = 0.0    # read empty: nothing sent to us is unread
                self._timers(t_read)
                link.wait(min(MAX_WAIT, max(0.0, self.timers.next_timer - clock())))
                continue
            kind = msg.get_type()
            if kind == "LOCAL_POSITION_NED":
                on_position(msg, t_read)
            elif kind == "ATTITUDE":
                attitude(msg)
            elif kind == "HEARTBEAT":
                self._on_heartbeat(msg)
            elif kind == "COMMAND_ACK":
                self._on_ack(msg)
            elif kind == estimate_kind:
                self._on_estimate(msg, t_read)
            elif (kind in ("MISSION_CURRENT", "MISSION_ITEM_REACHED")
                  and self.ground.handover is not None and link.is_vehicle(msg)):
                self.ground.handover.on_message(msg, self)
            elif kind in ("COMMAND_LONG", "COMMAND_INT") and self.ground.gcs is not None:
                self.ground.gcs.on_command(msg, self._on_request)   # DO_PAUSE_CONTINUE, ACKed
            elif kind == "STATUSTEXT" and link.is_vehicle(msg):
                text = "".join(c if c.isprintable() else "?" for c in msg.text)
                self.log("vehicle says: " + text)
                cause = self.autopilot_fs.text(text, t_read)
                if self.state is State.TRACKING and self.autopilot_fs.setpoints_lost(cause):
                    # telemetry flows but our setpoints do not arrive: the reference is held
                    # until the vehicle answers us again (our HOLD: see _may_recover)
                    self._failsafe(t_read, f'the vehicle says our setpoints stopped arriving '
                                   f'("{text}"): the link is silent towards it',
                                   cause="setpoints")
            if t_read >= self.timers.next_timer:
                self._timers(t_read)

    # --- per message ------------------------------------------------------------------------
    def _on_position(self, msg: Any, t_read: float) -> None:
        s = self.telemetry.position(msg)
        if s is None:
            if t_read >= self.timers.next_refusal_log:
                self._log_refusals(t_read)
            return
        heard = self.heard
        heard.sample_wall = t_read
        prev_vt, heard.vehicle_t = heard.vehicle_t, s.t
        heard.pose = (s.x, s.y, s.yaw)
        state = self.state
        step = self.estimate.position(s.t, s.x, s.y, s.vx, s.vy, t_read)
        if (step is not None and state in (State.TRACKING, State.ENGAGING)
                and not self.engagement.first(state)):
            # The stepped sample never reaches the controller as an error to chase.
            self._bad_estimate(step, t_read, s.time_boot_ms)
            state = self.state
            if state is State.DONE:
                return
        if state is State.TRACKING:
            clock = self.clock
            if clock.segment_t0 is not None and s.t - prev_vt > clock.max_gap:
                self._new_segment(s.t - prev_vt)
            self._track(s, t_read)
        else:
            if state is State.FAILSAFE and self._may_recover(t_read):
                self._recover()
            elif state is State.WAITING:
                problem = self._start_problem(self.mission, s.x, s.y, s.yaw)
                if problem is not None:
                    # Nothing has moved: a user's problem (exit 2), the vehicle left as it is.
                    self._finish(problem, ExitCode.USER_ERROR, hold=False, stop=False)
                    return
                self.log(f"telemetry flowing; engaging {self.track_mode}")
                self._enter_engaging(State.WAITING)
            if self.ground.handover is None or not self.ground.handover.quiet:
                self.link.send_stop(s.time_boot_ms)   # (not while AUTO drives itself)
            if self.state is State.ENGAGING:
                if self.engagement.warm_t0 is None:
                    self.engagement.warm_t0 = s.t
                self._engage(t_read)
        heard.waited = False

    def _start_problem(self, mission: Any, x: float, y: float, yaw: float) -> str | None:
        """Why ``mission`` must not start with the rover at (x, y, yaw), or None."""
        limit = self.config.max_start_distance
        if not (math.isfinite(limit) and limit > 0):
            return None
        ref = mission.anchored(x, y, yaw).sample(0.0)
        distance = math.hypot(ref.x - x, ref.y - y)
        if not distance > limit:
            return None
        where = (f" ({mission.frame} frame: {ref.x:.1f} m north, {ref.y:.1f} m east of the "
                 "EKF origin)" if mission.frame == "local" else "")
        return (f"'{mission.name}' starts {distance:.1f} m from the rover{where}, more than "
                f"--max-start-distance {limit:g} m: bring the rover nearer its first point or "
                "raise the limit (0: no limit)")

    def _heartbeat_fresh(self, now: float) -> bool:
        return now - self.heard.heartbeat_wall <= self.config.heartbeat_lost

    def _new_segment(self, gap: float) -> None:
        """Samples resume after a gap: forget the filter and integrators (no huge-dt step)."""
        self.tracker.reset()
        self.counters.tracker_resets += 1
        self.stats.lost(gap)
        self.clock.segment_t0 = None
        self.log(f"{gap:.3f} s of vehicle time without a sample: filter and integrators reset")

    def _log_refusals(self, now: float) -> None:
        """At most one line a second: how many samples were refused, and why."""
        self.timers.next_refusal_log = now + 1.0
        counts = _nonzero(self.telemetry.rejected)
        if counts != self.counters.refusals_logged:
            self.counters.refusals_logged = counts
            self.log(f"refused telemetry so far (never used): {counts}")

    def _track(self, s: Sample, t_read: float) -> None:
        clock = self.clock
        if clock.segment_t0 is None:
            if self.trajectory is None:
                self.trajectory = self.mission.anchored(s.x, s.y, s.yaw)
            clock.segment_t0 = s.t
            clock.offset = clock.time
            self.stats.segment_start()
        mt = clock.offset + (s.t - clock.segment_t0)
        clock.time = mt
        if mt >= self.mission.duration - 1e-9 and self.ground.handover is not None:
            self._hand_back(s.time_boot_ms)
            return
        if mt >= self.mission.duration - 1e-9:
            self._emit(ev.MISSION_DONE, f"{self.mission.duration:g} s of mission tracked")
            self._finish("mission_done", ExitCode.OK, s.time_boot_ms)
            return
        if getattr(self.tracker, "finished", False):       # a script with nothing more to ask
            self._emit(ev.MISSION_DONE, f"{mt:.1f} s of mission tracked: the script is over")
            self._finish("mission_done", ExitCode.OK, s.time_boot_ms)
            return
        assert self.trajectory is not None   # anchored when tracking began
        ref = self.trajectory.sample(mt)
        cmd = self.tracker.step(s.t, Measurement(s.x, s.y, s.yaw, s.vx, s.vy, s.yaw_rate), ref)
        problem = self._check(cmd)
        if problem is not None:
            self._emit(ev.FAILSAFE, problem)
            self._finish(f"failsafe: {problem}", ExitCode.FAULT, s.time_boot_ms)
            return
        self.link.send_command(cmd, s.time_boot_ms)
        latency = time.perf_counter() - t_read
        ex, ey = ref.x - s.x, ref.y - s.y
        e2 = ex * ex + ey * ey
        self.stats.add(mt, s.t, e2, latency, not self.heard.waited)
        if self.sinks:
            self._record(s, mt, ref, cmd, e2)

    def _check(self, cmd: Command) -> str | None:
        """Why this command must not be sent, or None. Right before encoding, every cycle."""
        speed, rate, ux, uy = cmd.speed, cmd.yaw_rate, cmd.ux, cmd.uy
        if not (_finite(speed) and _finite(rate) and _finite(ux) and _finite(uy)):
            return (f"controller output not finite (speed {speed!r}, yaw rate {rate!r}, "
                    f"u_p ({ux!r}, {uy!r})): stopping the rover")
        lim = self.limits
        if (abs(speed) > lim.max_speed * (1 + 1e-9) or abs(rate) > lim.max_yaw_rate * (1 + 1e-9)
                or math.hypot(ux, uy) > lim.max_speed * (1 + 1e-9)):
            return (f"controller output outside the limits (speed {speed:.3f} m/s, yaw rate "
                    f"{rate:.3f} rad/s): stopping the rover")
        return None

    def _record(self, s: Sample, mt: float, ref: Reference, cmd: Command, e2: float) -> None:
        est = self.tracker.estimate
        yaw_ref = math.atan2(cmd.uy, cmd.ux)
        err_yaw = math.remainder(yaw_ref - est.yaw, 2 * math.pi)
        rec = LoopRecord(s.t, mt, s.x, s.y, s.yaw, est.x, est.y, est.yaw, ref.x, ref.y,
                         math.sqrt(e2), err_yaw, cmd.ux, cmd.uy, cmd.speed, cmd.yaw_rate,
                         self.link.mode, self.link.armed)
        for sink in self.sinks:
            self._safely(sink.record, rec)

    def _on_heartbeat(self, msg: Any) -> None:
        if not self.link.is_vehicle_heartbeat(msg):
            return
        self.heard.heartbeat_wall = time.perf_counter()
        if self.heard.heartbeat_lost_said:
            self.heard.heartbeat_lost_said = False
            self.log("vehicle heartbeat back")
        mode, armed = self.link.mode, self.link.armed
        state, now = self.state, self.heard.heartbeat_wall
        self.autopilot_fs.heartbeat(msg.system_status)
        e = self.engagement
        if not self.profile.settled(e.start_mode):
            e.start_mode = mode          # still starting (ArduPilot's INITIALISING): its own
        if state in ACTIVE and mode == self.track_mode and not e.need_ack:
            e.mode_seen = True
        if self._not_yet_engaged(state) and mode != self.track_mode and (
                mode != e.start_mode or e.mode_seen):
            self._chosen_before_engaged(mode, now)
            return
        if state in (State.READY, State.TRACKING, State.PAUSED) and e.mode_seen:
            if mode != self.track_mode:
                self._left(mode, now, stalled=False)
            elif not armed:
                active = self.autopilot_fs.active(now)
                if active is not None and active[0] not in self.profile.failsafe.link_causes:
                    self._autopilot_took(f"the autopilot's {active[0]} failsafe ({active[1]}) "
                                         "disarmed the vehicle", now)
                else:
                    self._override("vehicle disarmed by someone else")
        elif state is State.FAILSAFE and mode != self.track_mode:
            self._left(mode, now, stalled=self.stopping.cause in ("telemetry", "heartbeat"))
        elif (state is State.ENGAGING and self.engagement.after_failsafe
              and mode not in (self.track_mode, self.hold_mode)):
            # Back from a failsafe, the vehicle shows a mode neither we nor our HOLD chose (the
            # heartbeat that says so often comes only after the link): judged as in the
            # failsafe (against our own HOLD request); an autopilot's failsafe or a pilot ends
            # the run, or (--retake-after-failsafe) the failsafe waits for it to clear.
            self.state = State.FAILSAFE
            self._left(mode, now, stalled=self.stopping.cause in ("telemetry", "heartbeat",
                                                                  "link"))
            if self.state is State.FAILSAFE and self.stopping.cause != "autopilot":
                self.state = State.ENGAGING
        if self.state is State.ENGAGING:
            self._engage(time.perf_counter())

    def _not_yet_engaged(self, state: State) -> bool:
        """Setting up, or engaging the first time on our own (not --start-on-guided /
        --handover, where the pilot or AUTO chooses the modes): the vehicle is not ours yet."""
        return (not self.config.wait_for_mode
                and (state is State.WAITING or self.engagement.first(state)))

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

    def _on_ack(self, msg: Any) -> None:
        if not self.link.is_vehicle(msg) or not self.link.is_for_us(msg):
            return
        if msg.command == 176 and self.mode_request.name is not None:   # MAV_CMD_DO_SET_MODE
            if msg.result == 0:
                if self.mode_request.name == self.hold_mode:
                    self.stopping.hold_confirmed = True
                elif self.state is State.ENGAGING:
                    # heartbeats from here on say what the vehicle did with our requests
                    self.engagement.need_ack = False
            else:
                self.log(f"vehicle refused mode {self.mode_request.name} (COMMAND_ACK result "
                         f"{msg.result})")
        elif msg.command == 400 and msg.result != 0:               # MAV_CMD_COMPONENT_ARM_DISARM
            self.log(f"vehicle refused to arm (COMMAND_ACK result {msg.result}); retrying")

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
                          f"{_nonzero(t.rejected)})" if t.received else "")
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

    def _autopilot_took(self, why: str, now: float) -> None:
        """The autopilot's own failsafe has the vehicle: never taken back on our own (nor
        taken at all, --retake-after-failsafe or not, when it was never ours)."""
        never_ours = self._not_yet_engaged(self.state)
        if not self.config.retake_after_failsafe or never_ours:
            self.log(f"{why}: not taking the vehicle{'' if never_ours else ' back'}; "
                     "no more setpoints")
            self._emit(ev.AUTOPILOT_FAILSAFE, why)
            self._finish(f"autopilot_failsafe: {why}", ExitCode.AUTOPILOT_FAILSAFE, hold=False,
                         stop=False)
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
        elif stopping.cause == "setpoints":
            self._finish(f"failsafe: the vehicle did not answer the companion for "
                         f"{cfg.lost_timeout:g} s (its setpoints stopped arriving)",
                         ExitCode.FAULT)
        else:
            self._finish(f"failsafe: telemetry lost for {cfg.lost_timeout:g} s", ExitCode.FAULT)

    # --- engaging: mode, then arming ---------------------------------------------------------
    def _enter_engaging(self, resume_to: State) -> None:
        self.state = State.ENGAGING
        e = self.engagement
        if resume_to in (State.TRACKING, State.PAUSED, State.READY):
            e.after = resume_to
        e.since = time.perf_counter()
        e.mode_seen, e.warm_t0, e.next_arm_try = False, None, 0.0
        self.mode_request.name, self.mode_request.next_try = None, 0.0
        self.clock.segment_t0 = None

    def _request_mode(self, name: str, now: float) -> None:
        self.mode_request.name = name
        self.link.request_mode(name)
        self.mode_request.next_try = now + self.config.retry_interval

    def _engage(self, now: float) -> None:
        cfg, link, e = self.config, self.link, self.engagement
        first = self._not_yet_engaged(self.state)
        if first and self.estimate.reports == 0 and (
                e.warm_t0 is None or self.heard.vehicle_t - e.warm_t0 < FIRST_REPORT_GRACE):
            return
        if cfg.wait_for_mode:
            # --start-on-guided / --handover: the flags alone (AUTO may reach the hand-over
            # item soon after they clear; waiting healthy_for more would miss it)
            problem = self.estimate.problem(now)
        elif first and not self.estimate.healthy(now):
            problem = (self.estimate.problem(now)
                       or f"not yet healthy for {cfg.estimate_healthy_for:g} s")
        else:
            problem = None
        if problem is not None:
            if not e.said_estimate_wait:
                e.said_estimate_wait = True
                self.log(f"waiting for a healthy position estimate before "
                         f"{'tracking' if cfg.wait_for_mode else 'engaging'} ({problem})")
            if first and now - e.since > cfg.estimate_wait:
                self._finish(f"estimate_unhealthy: no healthy position estimate within "
                             f"{cfg.estimate_wait:g} s of start ({problem}): wait for the GPS "
                             "fix and the EKF, or raise --estimate-wait",
                             ExitCode.ESTIMATE_UNHEALTHY)
            e.estimate_waited = True
            return
        if e.estimate_waited:
            # the mode and arm timeouts count from the moment there was something to engage
            e.estimate_waited, e.since = False, now
        warmup = self.profile.offboard_warmup
        if warmup is not None and (e.warm_t0 is None or self.heard.vehicle_t - e.warm_t0 < warmup):
            return   # the vehicle refuses the track mode until setpoints have streamed a while
        # Only a heartbeat that arrived since engaging began counts: after an outage the last
        # one still says GUIDED while the vehicle sits in the HOLD we sent it.
        if not e.mode_seen:
            if cfg.wait_for_mode:         # --start-on-guided: the pilot or a GCS engages
                if not e.said_arm_wait:
                    e.said_arm_wait = True
                    self.log(f"waiting for the pilot or a ground station to select "
                             f"{self.track_mode} and arm")
                return
            if now - e.since > cfg.mode_timeout:
                self._finish(f"failsafe: the vehicle did not enter {self.track_mode} within "
                             f"{cfg.mode_timeout:g} s", ExitCode.FAULT)
            elif now >= self.mode_request.next_try:
                self._request_mode(self.track_mode, now)
            return
        if not link.armed:
            if cfg.wait_for_mode:
                return
            if now - e.since > cfg.arm_timeout:
                self._finish(f"failsafe: the vehicle was not armed within {cfg.arm_timeout:g} s"
                             + ("" if cfg.arm else " (use --arm to arm it from here)"), ExitCode.FAULT)
            elif cfg.arm and now >= e.next_arm_try:
                link.request_arm()
                e.next_arm_try = now + cfg.retry_interval
            elif not cfg.arm and not e.said_arm_wait:
                e.said_arm_wait = True
                self.log("waiting for the vehicle to be armed (or pass --arm)")
            return
        target = e.after
        self.state = target
        if target is State.TRACKING:
            self.log(f"{self.track_mode} and armed: tracking '{self.mission.name}'")
            self._emit(ev.TRACKING, self.mission.name)
        elif target is State.READY:
            self.log(f"{self.track_mode} and armed: ready, waiting for `start`")

    # --- stopping -----------------------------------------------------------------------------
    def _finish(self, reason: str, code: ExitCode, time_boot_ms: int = 0, hold: bool = True,
                stop: bool = True) -> None:
        """Stop the rover (zero setpoint, then HOLD) and end the loop."""
        if stop:
            self.link.send_stop(time_boot_ms)
        if hold:
            stopping = self.stopping   # a HOLD confirmed in failsafe stands; an older one not
            stopping.hold_confirmed = stopping.hold_confirmed and self.state is State.FAILSAFE
            self._request_mode(self.hold_mode, time.perf_counter())
        self.state = State.DONE
        self.outcome = Outcome(reason, code, False, self.counters.failsafes)
        self.stopping.wants_hold = hold
        self.log(f"stopped: {reason}")

    def _override(self, why: str) -> None:
        if self.telemetry.backwards_streak:
            # Its clock went back too: not a pilot but a reboot (back in its boot mode).
            self._finish(REBOOTED, ExitCode.VEHICLE_RESTARTED)
            return
        # The pilot has the vehicle: not one more setpoint (not even a zero one), no mode
        # request. Setpoints outside GUIDED / OFFBOARD are ignored anyway, but a companion
        # that keeps talking to a vehicle someone else drives is one bug away from fighting.
        # The loop ends here; a rebooted autopilot looks the same (its boot mode, disarmed)
        # until its clock is read, after the loop (_judge_override).
        self.stopping.unjudged = why
        self.stopping.ask_clock = (time.perf_counter() - self.heard.sample_wall
                                   > self.config.stale_timeout)
        self.stopping.wants_hold = False
        self.state = State.DONE
        self.outcome = Outcome(f"pilot_override: {why}", ExitCode.PILOT_OVERRIDE, False,
                               self.counters.failsafes)

    def _judge_override(self, why: str) -> None:
        """A pilot, or a reboot? The vehicle's clock decides; then end with that reason."""
        self.stopping.unjudged = None
        last_ms = self.telemetry.last_ms
        clock_ms = self._read_vehicle_clock(ask=self.stopping.ask_clock)
        if clock_ms is not None and clock_went_back(last_ms, clock_ms):
            self.log(f"the vehicle's clock reads {clock_ms / 1e3:.3f} s, its last sample said "
                     f"{(last_ms or 0) / 1e3:.3f} s: it rebooted (what looked like a pilot: {why})")
            self._finish(REBOOTED, ExitCode.VEHICLE_RESTARTED)
            return
        self.log(f"pilot took over ({why}): no more setpoints")
        self._emit(ev.PILOT_OVERRIDE, why)
        self._finish(f"pilot_override: {why}", ExitCode.PILOT_OVERRIDE, hold=False, stop=False)

    def _read_vehicle_clock(self, ask: bool) -> int | None:
        """The vehicle's time_boot_ms from the first of its messages that carries one, read
        for CLOCK_LISTEN s, then (``ask``) asked for (SYSTEM_TIME), up to CLOCK_WAIT s; None
        if none came."""
        link, clock = self.link, time.perf_counter
        start = clock()
        ask_at = start + CLOCK_LISTEN
        while (now := clock()) < start + CLOCK_WAIT:
            msg = link.recv()
            if msg is None:
                if ask and now >= ask_at:
                    link.request_message(2)          # MAVLINK_MSG_ID_SYSTEM_TIME
                    ask_at = now + 0.5
                link.wait(min(0.05, max(0.0, start + CLOCK_WAIT - now)))
            elif msg.get_type() in CLOCK_KINDS and link.is_vehicle(msg):
                return int(msg.time_boot_ms)
        return None

    def _wait_for_hold(self) -> None:
        """Until HOLD shows (ACK or heartbeat), answer telemetry with zero setpoints."""
        if not self.stopping.wants_hold:
            return
        link, clock = self.link, time.perf_counter
        deadline = clock() + self.config.hold_timeout
        retry = clock() + 0.5
        while not self.stopping.hold_confirmed and (now := clock()) < deadline:
            msg = link.recv()
            if msg is None:
                if now >= retry:
                    link.send_stop()
                    self._request_mode(self.hold_mode, now)
                    retry = now + 0.5
                link.wait(min(0.05, deadline - now))
                continue
            kind = msg.get_type()
            if kind == "ATTITUDE":
                self.telemetry.attitude(msg)
            if not link.is_vehicle(msg):
                continue
            if kind == "LOCAL_POSITION_NED":
                sample = self.telemetry.position(msg)   # bad ones get no answer, even now
                if sample is not None:
                    link.send_stop(sample.time_boot_ms)
            elif (kind == "HEARTBEAT" and link.is_vehicle_heartbeat(msg)
                  and link.mode == self.hold_mode):
                self.stopping.hold_confirmed = True
            elif kind == "COMMAND_ACK":
                self._on_ack(msg)
        if not self.stopping.hold_confirmed:
            self.log(f"{self.hold_mode} not confirmed by the vehicle within "
                     f"{self.config.hold_timeout:g} s")

    # --- control channel ------------------------------------------------------------------------
    def _on_request(self, req: ControlRequest) -> None:
        verb, state = req.verb, self.state
        if verb == "status":
            req.reply(True, json.dumps(self.status()))
        elif verb == "start" and self.ground.handover is not None:
            req.reply(False, "--handover: AUTO starts each segment, not `start`")
        elif verb == "start":
            if state is State.READY:
                self.state = State.TRACKING
                self.clock.segment_t0 = None
                self._emit(ev.TRACKING, self.mission.name)
                req.reply(True, f"tracking '{self.mission.name}'")
            else:
                req.reply(False, f"cannot start while {state.value}")
        elif verb == "pause":
            if state is State.TRACKING:
                self.state = State.PAUSED
                self._emit(ev.PAUSED, "requested")
                req.reply(True, f"paused at mission time {self.clock.time:.2f} s")
            else:
                req.reply(False, f"cannot pause while {state.value}")
        elif verb == "resume":
            if state is State.PAUSED:
                self.tracker.reset()   # the rover stood still: start the filter afresh
                self.state = State.TRACKING
                self.clock.segment_t0 = None
                self._emit(ev.RESUMED, "requested")
                req.reply(True, f"resumed at mission time {self.clock.time:.2f} s")
            else:
                req.reply(False, f"cannot resume while {state.value}")
        elif verb == "abort":
            self._finish("aborted", ExitCode.OK)
            req.reply(True, "stopping the rover")
        elif verb == "load-mission":
            self._load_mission(req)
        else:
            req.reply(False, f"unknown verb {verb!r}")

    def _load_mission(self, req: ControlRequest) -> None:
        if self.state not in (State.WAITING, State.ENGAGING, State.READY, State.PAUSED):
            req.reply(False, f"cannot load a mission while {self.state.value}: pause first")
            return
        from .. import mission as missions
        text = req.payload.strip()
        try:
            path = Path(text)
            local_file = (req.allow_path and "\n" not in text and path.suffix != ""
                          and path.exists())
            origin = self.origin
            new = (missions.load(path, origin=origin) if local_file
                   else missions.loads(text, "<load-mission>", origin=origin))
        except UserError as err:
            req.reply(False, str(err))
            return
        if new.geodetic and self.origin is None:
            req.reply(False, f"'{new.name}' is placed by latitude / longitude and this run has "
                             "not read the vehicle's EKF origin: start the run with a geodetic "
                             "mission to fly one")
            return
        problem = self.heard.pose and self._start_problem(new, *self.heard.pose)
        if problem:
            req.reply(False, problem)
            return
        self.mission, self.trajectory = new, None
        self.clock.time, self.clock.offset, self.clock.segment_t0 = 0.0, 0.0, None
        self.stats = TrackingStats(new.duration, self.config.period)
        if self.state is State.PAUSED:
            self.state = State.READY
            self.tracker.reset()
        self.engagement.after = State.READY
        self._emit(ev.MISSION_LOADED, new.name, {"source": new.source, "duration": new.duration})
        req.reply(True, f"loaded '{new.name}' ({new.duration:g} s); send `start`")

    # --- hand-over inside AUTO (companion.live.handover calls these) ---------------------------
    def handover_pose(self) -> tuple[float, float, float] | None:
        """The rover's last pose, if the loop is engaged (AUTO and armed) and may track."""
        return self.heard.pose if self.state is State.READY else None

    def handover_begin(self, mission: Any) -> None:
        """AUTO reached a NAV_GUIDED_ENABLE: track ``mission`` (from the rover's pose) now."""
        self.mission, self.trajectory = mission, None
        self.clock.time, self.clock.offset, self.clock.segment_t0 = 0.0, 0.0, None
        self.stats = TrackingStats(mission.duration, self.config.period)
        self.tracker.reset()
        self.state = State.TRACKING
        self.log(f"hand-over: tracking '{mission.name}' ({mission.duration:.1f} s)")
        self._emit(ev.TRACKING, mission.name)

    def _hand_back(self, time_boot_ms: int) -> None:
        self.link.send_stop(time_boot_ms)
        segment = self.ground.handover.hand_back()
        self.handover_ended(f"handed back to AUTO at item {segment.resume_seq}", True)

    def handover_ended(self, why: str, handed_back: bool) -> None:
        """The segment is over (done, or AUTO took it back): silent until the next one."""
        from .handover import SegmentResult
        st = self.stats
        seg = self.ground.handover.handing_back if handed_back else None
        items = (seg.enable_seq, seg.resume_seq) if seg else (self.ground.handover.current, -1)
        self.ground.handover.results.append(SegmentResult(items[0], items[1], self.clock.time,
                                                   st.steady_rms, st.f_cost, why))
        if self.state in (State.TRACKING, State.PAUSED):
            self.state = State.READY
        self.log(f"hand-over: {why}; steady RMS {st.steady_rms:.3f} m over "
                 f"{self.clock.time:.1f} s")
        self._emit(ev.HANDED_BACK, why, {"steady_rms": st.steady_rms})

    def handover_finished(self, reason: str) -> None:
        """AUTO completed the mission: the run ends, the vehicle left as AUTO leaves it."""
        self._emit(ev.MISSION_DONE, reason)
        self._finish(f"mission_done: {reason}", ExitCode.OK, hold=False, stop=False)

    def status(self) -> dict[str, Any]:
        t = self.telemetry
        return {"state": self.state.value, "mission": self.mission.name,
                "track_mode": self.track_mode,
                "mission_time": self.clock.time, "duration": self.mission.duration,
                "mode": self.link.mode, "armed": self.link.armed, "cycles": self.stats.cycles,
                "telemetry_received": t.received, "telemetry_rejected": dict(t.rejected),
                "failsafes": self.counters.failsafes,
                "signing_rejected": getattr(self.link, "signing_rejected", 0)}

    # --- sinks ------------------------------------------------------------------------------
    def _emit(self, kind: str, reason: str = "", detail: dict | None = None) -> None:
        if not self.sinks:
            return
        event = StatusEvent(kind, reason, self.heard.vehicle_t or None, detail or {})
        for sink in self.sinks:
            self._safely(sink.status, event)

    def _safely(self, fn: Callable[..., object], *args: Any) -> None:
        """A failing sink (a full disk, a dead network) must never stop the control loop."""
        try:
            fn(*args)
        except Exception as exc:  # noqa: BLE001
            self.counters.sink_errors += 1
            if self.counters.sink_errors == 1:
                self.log(f"a sink failed ({type(exc).__name__}: {exc}); carrying on")


def stop_cause(code: int) -> str:
    """The exit code's name, lower case ("ok", "pilot_override", "autopilot_failsafe"...): the
    JSON's and the Zenoh status's ``stop_cause``."""
    return ExitCode(code).name.lower()


def _nonzero(counts: dict[str, int]) -> dict[str, int]:
    return {k: v for k, v in counts.items() if v}
