"""Ending a run: the rover stopped (zero setpoint, then HOLD), or left alone when a pilot has it.

A pilot's takeover ends the loop at once, without another message to the vehicle; whether it
was a pilot, a reboot (the autopilot comes back in its boot mode, disarmed, just as a pilot's
switch looks) or the autopilot's own failsafe whose word came just after its mode change
(ArduPilot's battery failsafe: the HOLD heartbeat first, its "Battery 1 is low" and SYS_STATUS
within 30 ms) is judged after the loop, from the vehicle's clock and what it says meanwhile.
The HOLD the companion asked for is waited for, answering telemetry with zero setpoints
meanwhile.
"""

from __future__ import annotations

import time

from ...errors import ExitCode
from .. import events as ev
from .. import health
from ..loop_state import Outcome, State
from ..telemetry import clock_went_back
from .core import LoopCore

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
# and for at least this long (wall s) for the autopilot's STATUSTEXT or SYS_STATUS naming a
# failsafe of its own that made the change
FAILSAFE_LISTEN = 0.5


class Ending(LoopCore):
    """Stopping the rover and ending the loop; a pilot's takeover told from a reboot."""

    def _finish(self, reason: str, code: ExitCode, time_boot_ms: int = 0, hold: bool = True,
                stop: bool = True, asked: bool = False) -> None:
        """Stop the rover (zero setpoint, then HOLD) and end the loop; a vehicle nothing was
        asked of yet is left as it is (:meth:`_untouched`), and so is one AUTO drives between
        hand-overs when the operator stops the run (``asked``: a signal, ``abort``)."""
        left = ""
        if (stop or hold) and self._untouched():
            stop = hold = False
            left = f" (nothing had been asked of the vehicle: left as it was, in {self.link.mode})"
        elif (stop or hold) and asked and self._auto_drives():
            stop = hold = False
            left = (f" (AUTO drives its own mission items: left to it, in {self.link.mode}; "
                    "the segments still ahead will not be tracked)")
        if stop:
            self.link.send_stop(time_boot_ms)
        if hold:
            stopping = self.stopping   # a HOLD confirmed in failsafe stands; an older one not
            stopping.hold_confirmed = stopping.hold_confirmed and self.state is State.FAILSAFE
            self._request_mode(self.hold_mode, time.perf_counter())
        self.state = State.DONE
        self.outcome = Outcome(reason, code, False, self.counters.failsafes)
        self.stopping.wants_hold = hold
        self.log(f"stopped: {reason}{left}")

    def _untouched(self) -> bool:
        """Nothing has been asked of the vehicle yet: no mode, no arming (setting up, or the
        first engagement before its first mode request: waiting for a healthy estimate, or with
        --start-on-guided / --handover for the pilot or AUTO). A stop then (Ctrl-C, ``abort``,
        the estimate never healthy) sends nothing: the vehicle may be a pilot's to drive, and
        a HOLD would stop it under them. Zero setpoints sent meanwhile went to a vehicle outside
        GUIDED / OFFBOARD, which ignores them."""
        return self.state is State.WAITING or (self.engagement.first(self.state)
                                               and self.mode_request.name is None)

    def _auto_drives(self) -> bool:
        """--handover, between segments: AUTO flies its own items and the companion sends no
        setpoint. Stopping the companion then is no reason to stop the autopilot's mission (a
        HOLD would). That includes a segment's hand-back (its path done, a zero setpoint sent,
        AUTO told to go on); a segment being tracked is the companion's to stop."""
        handover = self.ground.handover
        return handover is not None and handover.quiet and self.state is State.READY

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
        # The same verdicts as in the loop, now with what the autopilot said just after
        now, mode, fs = time.perf_counter(), self.link.mode, self.autopilot_fs
        who, took = (fs.who_left(mode, self.hold_mode, now, companion_stalled=False,
                                 hold_asked=False)
                     if mode != self.track_mode else fs.who_disarmed(now))
        if who == health.AUTOPILOT:
            self.log(f"the autopilot named its failsafe just after the change ({why})")
            self._end_for_autopilot(took)
            return
        self.log(f"pilot took over ({why}): no more setpoints")
        self._emit(ev.PILOT_OVERRIDE, why)
        self._finish(f"pilot_override: {why}", ExitCode.PILOT_OVERRIDE, hold=False, stop=False)

    def _end_for_autopilot(self, why: str, back: bool = True) -> None:
        """The autopilot's own failsafe has the vehicle, and the companion does not take it
        (back): say so and end, sending nothing more."""
        self.log(f"{why}: not taking the vehicle{' back' if back else ''}; no more setpoints")
        self._emit(ev.AUTOPILOT_FAILSAFE, why)
        self._finish(f"autopilot_failsafe: {why}", ExitCode.AUTOPILOT_FAILSAFE, hold=False,
                     stop=False)

    def _read_vehicle_clock(self, ask: bool) -> int | None:
        """The vehicle's time_boot_ms from the first of its messages that carries one, read
        for CLOCK_LISTEN s, then (``ask``) asked for (SYSTEM_TIME), up to CLOCK_WAIT s; None
        if none came. Meanwhile, for at least FAILSAFE_LISTEN s, its STATUSTEXTs and
        SYS_STATUS go to the failsafe watch (until one names a failsafe)."""
        link, clock = self.link, time.perf_counter
        start = clock()
        ask_at = start + CLOCK_LISTEN
        clock_ms: int | None = None
        named = False
        while (now := clock()) < start + CLOCK_WAIT:
            if clock_ms is not None and (named or now >= start + FAILSAFE_LISTEN):
                break
            msg = link.recv()
            if msg is None:
                if ask and clock_ms is None and now >= ask_at:
                    link.request_message(2)          # MAVLINK_MSG_ID_SYSTEM_TIME
                    ask_at = now + 0.5
                link.wait(min(0.05, max(0.0, start + CLOCK_WAIT - now)))
                continue
            kind = msg.get_type()
            if not link.is_vehicle(msg):
                continue
            if kind in CLOCK_KINDS and clock_ms is None:
                clock_ms = int(msg.time_boot_ms)
            elif kind in ("STATUSTEXT", "SYS_STATUS"):
                cause = self._autopilot_says(msg, now)
                named = named or (cause is not None
                                  and cause not in self.profile.failsafe.link_causes)
        return clock_ms

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
