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
    TRACKING / ENGAGING --the receiver below the run's class, the profile's policy "hold"
             (companion.live.gnss_watch)--> FAILSAFE (cause "gnss"); back once the class has
             been back for the policy's back_for, the mission clock where it stopped
    TRACKING --the policy's "slow"--> TRACKING with the mission clock at slow_factor
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

The loop's parts, each a class the next builds on (state is made once, in :mod:`.core`):
:mod:`.core` (state, mode requests, sinks) -> :mod:`.ending` (stopping, a pilot told from a
reboot) -> :mod:`.engaging` (mode, arming) -> :mod:`.failsafes` (timers, failsafe, recovery,
who left the track mode); :mod:`.requests` (control verbs, hand-over); this module, the loop
and what each message does.
"""

from __future__ import annotations

import gc
import math
import time
from collections.abc import Callable
from typing import Any

from ...core import pacing
from ...core.signals import Command, Measurement, Reference
from ...errors import ExitCode
from .. import events as ev
from .. import health
from ..events import LoopRecord
from ..loop_state import ACTIVE, Outcome, State
from ..telemetry import Sample
from .core import nonzero, printable, stop_cause
from .failsafes import Failsafes
from .requests import Requests

_finite = math.isfinite
MAX_WAIT = 0.05        # wall s: the longest sleep (so stop requests are seen promptly)
# wall s between two turns of the loop that only the companion's own stall explains (an
# overloaded board descheduled it): four of its longest sleeps
STALL = 4 * MAX_WAIT


class Runner(Failsafes, Requests):
    """The live control loop: :meth:`run` drives the vehicle until the run ends, and returns why."""

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
        # pose read right after its own ATTITUDE was consumed there is refused ("no_attitude";
        # seen: docs/benchmarks-log.md). Its vehicle time is checked as any attitude's: a stale
        # one serves no sample.
        held = link.last_heard("ATTITUDE")
        if held is not None:
            attitude(held)
        # Everything alive now (modules, pymavlink's tables) moves out of the collector's
        # reach, so a full collection during the loop scans only what the loop allocated, not
        # the imports (what a full one cost: docs/benchmarks-log.md).
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
                self._finish(self.stopping.requested, ExitCode.OK, asked=True)
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
            elif kind == "GPS_RAW_INT" and link.is_vehicle(msg):
                self._on_gnss(msg, t_read)
            elif kind == "STATUSTEXT" and link.is_vehicle(msg):
                cause = self._autopilot_says(msg, t_read)
                if self.state is State.TRACKING and self.autopilot_fs.setpoints_lost(cause):
                    # telemetry flows but our setpoints do not arrive: the reference is held
                    # until the vehicle answers us again (our HOLD: see _may_recover)
                    self._failsafe(t_read, f'the vehicle says our setpoints stopped arriving '
                                   f'("{printable(msg.text)}"): the link is silent towards it',
                                   cause="setpoints")
            elif kind == "SYS_STATUS" and link.is_vehicle(msg):
                self._autopilot_says(msg, t_read)
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
        heard.velocity = (s.vx, s.vy)
        state = self.state
        step = self.estimate.position(s.t, s.x, s.y, s.vx, s.vy, t_read)
        steer = self.gnss.jump.position(s.t, s.x, s.y, s.vx, s.vy)
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
            if self.gnss.jump.overdue(s.t):
                self._jump_overdue(t_read)
                return
            self._track(s, t_read, steer)
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
                who, why = self.autopilot_fs.who_disarmed(now)
                if who == health.AUTOPILOT:
                    self._autopilot_took(why, now)
                else:
                    self._override(why)
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

    def _new_segment(self, gap: float) -> None:
        """Samples resume after a gap: forget the filter and integrators (no huge-dt step)."""
        self.tracker.reset()
        self.counters.tracker_resets += 1
        self.stats.lost(gap)
        self.clock.segment_t0 = None
        self.clock.ramp_s = 0.0      # (the rover was moving: no ramp from rest)
        self.gnss.jump.forget()           # (no dead reckoning across the gap)
        self.log(f"{gap:.3f} s of vehicle time without a sample: filter and integrators reset")

    def _log_refusals(self, now: float) -> None:
        """At most one line a second: how many samples were refused, and why."""
        self.timers.next_refusal_log = now + 1.0
        counts = nonzero(self.telemetry.rejected)
        if counts != self.counters.refusals_logged:
            self.counters.refusals_logged = counts
            self.log(f"refused telemetry so far (never used): {counts}")

    def _jump_overdue(self, now: float) -> None:
        """Ridden through a receiver's jump for jump_max_ride: hold, then trust the estimate."""
        self.gnss.jump.forget()
        self.gnss.noted("hold", now)
        self._failsafe(now, f"the receiver's jump did not come back within "
                            f"{self.gnss.jump.max_ride:g} s of riding through: holding on the path",
                       cause="gnss")

    def _track(self, s: Sample, t_read: float, steer: tuple[float, float]) -> None:
        clock = self.clock
        if clock.segment_t0 is None:
            if self.trajectory is None:
                self.trajectory = self.mission.anchored(s.x, s.y, s.yaw)
            if clock.rejoin:
                self._rejoin(steer)
            clock.segment_t0 = s.t
            clock.offset = clock.time
            self.stats.segment_start()
        if clock.ramp_s > 0.0:
            advanced, ramp_rate, ramp_dot = pacing.ramp(s.t - clock.segment_t0, clock.ramp_s)
            if ramp_rate >= 1.0:
                clock.ramp_s = 0.0
                clock.offset, clock.segment_t0 = clock.offset + clock.rate * advanced, s.t
                advanced = 0.0
        else:
            advanced, ramp_rate, ramp_dot = s.t - clock.segment_t0, 1.0, 0.0
        mt = clock.offset + clock.rate * advanced
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
        if clock.rate != 1.0 or ramp_rate != 1.0:
            ref = pacing.paced(ref, clock.rate * ramp_rate, clock.rate * ramp_dot)
        # (steer: the estimate's position, or the rover's own motion through a receiver's jump)
        cmd = self.tracker.step(s.t, Measurement(steer[0], steer[1], s.yaw, s.vx, s.vy,
                                                 s.yaw_rate), ref)
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

    def _rejoin(self, at: tuple[float, float]) -> None:
        """After standing still: the mission time of the rover's place on the path (at or
        after where the clock stood: what it braked through was driven), and a ramp up to the
        reference's speed there at RunnerConfig.rejoin_accel (no flag sets it)."""
        clock = self.clock
        assert self.trajectory is not None
        clock.rejoin = False
        held = clock.time
        clock.time, clock.ramp_s = pacing.rejoin(self.trajectory, held, at[0], at[1],
                                                 self.mission.duration,
                                                 self.config.rejoin_accel, clock.rate)
        self.log(f"rejoining the path at mission time {clock.time:.2f} s (held at {held:.2f} s),"
                 f" up to speed over {clock.ramp_s:.1f} s")

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
