"""The live loop's state, made once, and what every part of it uses.

:class:`LoopCore` makes every attribute the loop has (the pieces of
:mod:`companion.live.loop_state`, the checks of :mod:`companion.live.telemetry` and
:mod:`companion.live.health`); the parts built on it (:mod:`.ending`, :mod:`.engaging`,
:mod:`.failsafes`, :mod:`.requests`) add behaviour and no state of their own. Here also: the
mode requests and the vehicle's answers to them, the status a ``status`` request gets, and the
sinks' events, which must never stop the loop.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from ...core.limits import Limits
from ...core.trajectory import Trajectory
from ...errors import ExitCode
from .. import health
from ..config import RunnerConfig, segment_gap
from ..events import ControlChannel, Sink, StatusEvent
from ..gnss_watch import GnssWatch
from ..link import Link
from ..loop_state import (
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
from ..stats import TrackingStats
from ..telemetry import TelemetryCheck


class LoopCore:
    """The loop's state, in the named pieces of :mod:`companion.live.loop_state`.

    ``link`` is the vehicle's MAVLink link (set up: streams, mode known); ``tracker`` the
    estimator + law (:class:`companion.core.tracker.Tracker`); ``mission`` the reference, anchored
    at the first tracking sample; ``sinks`` get records and events; ``control`` is polled once per
    cycle; ``gcs`` / ``handover`` are the ground station's and the AUTO hand-over's helpers.
    """

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
            config.estimate_healthy_for, max_step_dt=self.clock.max_gap,
            gnss=GnssWatch.of(self.profile.gnss))    # the receiver's class, and its jumps
        self.autopilot_fs = health.FailsafeWatch(self.profile.failsafe)

    @property
    def track_mode(self) -> str:
        return self.config.track_mode or self.profile.track_mode

    @property
    def gnss(self) -> GnssWatch:
        """The receiver's watch (the estimate's source): its class, and ``.jump``."""
        assert self.estimate.gnss is not None
        return self.estimate.gnss

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

    # --- asked from outside the loop --------------------------------------------------------
    def request_stop(self, reason: str) -> None:
        """Ask the loop to stop the rover and end (safe to call from a signal handler)."""
        if self.stopping.requested is None:
            self.stopping.requested = reason

    def status(self) -> dict[str, Any]:
        t = self.telemetry
        return status_fields(self.state.value, self.mission, self.track_mode, self.link.mode,
                             self.link, self.clock.time, self.stats.cycles, t.received,
                             dict(t.rejected), self.counters.failsafes,
                             gnss=self.gnss.status())

    # --- what the parts share ------------------------------------------------------------
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

    def _autopilot_says(self, msg: Any, now: float) -> str | None:
        """A STATUSTEXT or SYS_STATUS of the vehicle, logged and given to the failsafe watch:
        the failsafe cause it names, or None."""
        if msg.get_type() == "SYS_STATUS":
            cause = self.autopilot_fs.sys_status(msg.onboard_control_sensors_enabled,
                                                 msg.onboard_control_sensors_health, now)
            if cause is not None:
                self.log(f"vehicle's SYS_STATUS: {cause} unhealthy")
            return cause
        text = printable(msg.text)
        self.log("vehicle says: " + text)
        return self.autopilot_fs.text(text, now)

    def _heartbeat_fresh(self, now: float) -> bool:
        return now - self.heard.heartbeat_wall <= self.config.heartbeat_lost

    # --- mode requests and the vehicle's answers -------------------------------------------
    def _request_mode(self, name: str, now: float) -> None:
        self.mode_request.name = name
        self.link.request_mode(name)
        self.mode_request.next_try = now + self.config.retry_interval

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


def status_fields(state: str, mission: Any, track_mode: str | None, mode: str | None, link: Any,
                  mission_time: float = 0.0, cycles: int = 0, received: int = 0,
                  rejected: dict[str, int] | None = None, failsafes: int = 0,
                  gnss: dict[str, Any] | None = None) -> dict[str, Any]:
    """A ``status`` request's answer: the loop's (:meth:`LoopCore.status`) and, with the
    loop's counts at zero, the setup's (:mod:`companion.live.setup_answers`)."""
    return {"state": state, "mission": mission.name, "track_mode": track_mode,
            "mission_time": mission_time, "duration": mission.duration, "mode": mode,
            "armed": link.armed, "cycles": cycles, "telemetry_received": received,
            "telemetry_rejected": rejected or {}, "failsafes": failsafes,
            "signing_rejected": getattr(link, "signing_rejected", 0), "gnss": gnss or {}}


def printable(text: str) -> str:
    """A vehicle's STATUSTEXT as the companion repeats it: unprintable characters as "?"."""
    return "".join(c if c.isprintable() else "?" for c in text)


def stop_cause(code: int) -> str:
    """The exit code's name, lower case ("ok", "pilot_override", "autopilot_failsafe"...): the
    JSON's and the Zenoh status's ``stop_cause``."""
    return ExitCode(code).name.lower()


def nonzero(counts: dict[str, int]) -> dict[str, int]:
    """The counts that are not zero (refusal tallies in lines and errors)."""
    return {k: v for k, v in counts.items() if v}
