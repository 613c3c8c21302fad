"""Engaging: taking the vehicle into the track mode (GUIDED / OFFBOARD) and, with ``--arm``, arming it.

The first time, nothing is asked of the vehicle until its position estimate is healthy (a
vehicle just powered on has no position yet); PX4's offboard mode needs setpoints streaming
first (the profile's warm-up). Only a heartbeat that arrived since engaging began says the
vehicle is in the track mode. Then the loop tracks (or waits, READY, for ``start``).
"""

from __future__ import annotations

import time

from ...errors import ExitCode
from .. import events as ev
from ..loop_state import State
from .ending import Ending

# vehicle s of telemetry the first engagement waits for the estimator's first report (asked for
# at 5 Hz), so a vehicle that has no position yet is not engaged on the strength of no news
FIRST_REPORT_GRACE = 1.0


class Engaging(Ending):
    """Mode, then arming; the first engagement waits for a healthy estimate."""

    def _not_yet_engaged(self, state: State) -> bool:
        """Setting up, or engaging the first time on our own (not --start-on-guided /
        --handover, where the pilot or AUTO chooses the modes): the vehicle is not ours yet."""
        return (not self.config.wait_for_mode
                and (state is State.WAITING or self.engagement.first(state)))

    def _enter_engaging(self, resume_to: State) -> None:
        self.state = State.ENGAGING
        e = self.engagement
        if resume_to in (State.TRACKING, State.PAUSED, State.READY):
            e.after = resume_to
        e.since = time.perf_counter()
        e.mode_seen, e.warm_t0, e.next_arm_try = False, None, 0.0
        self.mode_request.name, self.mode_request.next_try = None, 0.0
        self.clock.segment_t0 = None

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
        if not self.gnss.begun:
            # the run's class, and what to expect of it, said before the rover moves
            said = self.gnss.begin()
            self.log(said)
            self._emit(ev.GNSS, self.gnss.short(), self.gnss.status())
        self.state = target
        if target is State.TRACKING:
            self.log(f"{self.track_mode} and armed: tracking '{self.mission.name}'")
            self._emit(ev.TRACKING, self.mission.name)
        elif target is State.READY:
            self.log(f"{self.track_mode} and armed: ready, waiting for `start`")
