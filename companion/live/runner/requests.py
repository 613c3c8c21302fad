"""What is asked of the loop from outside it: the control channel's verbs and the AUTO hand-over.

Verbs (``status``, ``start``, ``pause``, ``resume``, ``abort``, ``load-mission``) arrive through a
:class:`companion.live.events.ControlChannel` polled once per cycle (Zenoh, the ground station's
DO_PAUSE_CONTINUE) and are answered at once; a verb that does not fit the state is refused with
the reason. With ``--handover``, :mod:`companion.live.handover` calls the ``handover_*`` methods
as AUTO reaches and leaves its NAV_GUIDED_ENABLE items.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ...errors import ExitCode, UserError
from .. import events as ev
from ..events import ControlRequest
from ..loop_state import State
from ..stats import TrackingStats
from .ending import Ending


class Requests(Ending):
    """The control channel's verbs and the hand-over's calls."""

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
                self.clock.rejoin = True
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
            self._finish("aborted", ExitCode.OK, asked=True)
            req.reply(True, "stopping the rover" if self.stopping.wants_hold
                      else "stopped; the vehicle left as it was")
        elif verb == "load-mission":
            self._load_mission(req)
        else:
            req.reply(False, f"unknown verb {verb!r}")

    def _load_mission(self, req: ControlRequest) -> None:
        if self.state not in (State.WAITING, State.ENGAGING, State.READY, State.PAUSED):
            req.reply(False, f"cannot load a mission while {self.state.value}: pause first")
            return
        from ... import mission as missions
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
        self.clock.restart()
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
        self.clock.restart()
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
        from ..handover import SegmentResult
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
