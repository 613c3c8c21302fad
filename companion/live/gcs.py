"""The companion as a ground station sees it: STATUSTEXT, NAMED_VALUE_FLOAT, and the GCS's commands.

:class:`GcsReporter` is a :class:`~companion.live.events.Sink` on the vehicle's own MAVLink link:
every life-cycle event (engage, pause, resume, failsafe, pilot override, mission end, stop) and
every refusal becomes one STATUSTEXT of a fitting severity, at most 50 characters (what
QGroundControl, Mission Planner and MAVProxy show of one), and, at ``GCS_REPORT_HZ``, four
NAMED_VALUE_FLOAT values a GCS can plot (names of at most 10 characters; docs/ground-station.md):

    pzc_err    the tracking error |p_ref - p| of the last tracked sample, m
    pzc_state  the loop's state as a number (STATE_CODES)
    pzc_prog   mission progress, mission time / duration, 0..1
    pzc_mt     mission time, s

Both are broadcast (no target): ArduPilot routes them to its other links, so a GCS on its
telemetry radio sees them (ArduPilot's MAVLink routing; ``field-faults-and-gcs.md``).

:class:`GcsCommands` turns a GCS's MAV_CMD_DO_PAUSE_CONTINUE (193; param1 0 pause, 1 continue),
addressed to the companion (its system id and component 191, or broadcast), into the loop's own
``pause`` / ``resume`` request and answers it with a COMMAND_ACK: what the Zenoh ``control``
queryable does, from any GCS. The loop stays the only one that acts.

Pure text and numbers are made here by functions (:func:`statustext`, :func:`values`); the
sending is the link's pymavlink ``mav``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from ..errors import ExitCode
from . import events as ev
from .config import GCS_REPORT_HZ
from .events import ControlRequest, LoopRecord, StatusEvent

# MAV_SEVERITY (common.xml)
EMERGENCY, ALERT, CRITICAL, ERROR, WARNING, NOTICE, INFO, DEBUG = range(8)
TEXT_MAX = 50            # STATUSTEXT.text: 50 characters
PREFIX = "PZC: "
MAV_CMD_DO_PAUSE_CONTINUE = 193
LINGER_S = 0.3           # wall s between the last report and the link's closing
MAV_RESULT_ACCEPTED, MAV_RESULT_TEMPORARILY_REJECTED, MAV_RESULT_DENIED = 0, 1, 2

# pzc_state: the runner's State values as numbers (stable: a GCS graph or script reads them)
STATE_CODES = {"waiting": 0, "engaging": 1, "ready": 2, "tracking": 3, "paused": 4,
               "failsafe": 5, "done": 6}
VALUE_NAMES = ("pzc_err", "pzc_state", "pzc_prog", "pzc_mt")

# What each event says, and how loud.
_EVENT_TEXT = {
    ev.CONNECTED: (INFO, "connected"),
    ev.TRACKING: (NOTICE, "tracking"),
    ev.PAUSED: (NOTICE, "paused"),
    ev.RESUMED: (NOTICE, "resumed"),
    ev.MISSION_DONE: (NOTICE, "mission done"),
    ev.MISSION_LOADED: (INFO, "loaded"),
    ev.FAILSAFE: (CRITICAL, "FAILSAFE"),
    ev.PILOT_OVERRIDE: (WARNING, "pilot took over"),
    ev.AUTOPILOT_FAILSAFE: (CRITICAL, "autopilot failsafe"),
    ev.HANDED_BACK: (NOTICE, "hand-back"),
    ev.GNSS: (NOTICE, "GNSS"),
}


_STATE_TEXT = {"engaging": "engaging {mode}", "ready": "ready: {mode}, waiting to track"}


def fit(text: str, limit: int = TEXT_MAX) -> str:
    """``text`` as printable ASCII within ``limit`` characters ('...' where it was cut)."""
    clean = "".join(c if " " <= c <= "~" else "?" for c in text)
    return clean if len(clean) <= limit else clean[:limit - 3].rstrip() + "..."


def statustext(event: StatusEvent) -> tuple[int, str] | None:
    """(MAV_SEVERITY, text of <= 50 characters) for a life-cycle event, or None."""
    if event.kind == ev.STOPPED:
        code = event.detail.get("exit_code", ExitCode.OK)
        severity = {ExitCode.OK: NOTICE, ExitCode.USER_ERROR: ERROR}.get(code, CRITICAL)
        label = "refused" if code == ExitCode.USER_ERROR else "stopped"
        return severity, fit(f"{PREFIX}{label}: {event.reason}")
    known = _EVENT_TEXT.get(event.kind)
    if known is None:
        return None
    severity, label = known
    text = f"{PREFIX}{label}" + (f": {event.reason}" if event.reason else "")
    return severity, fit(text)


def values(status: dict[str, Any], err: float) -> tuple[tuple[str, float], ...]:
    """The NAMED_VALUE_FLOATs for a :meth:`Runner.status` and the last tracking error."""
    duration = float(status.get("duration") or 0.0)
    mt = float(status.get("mission_time") or 0.0)
    progress = min(1.0, mt / duration) if duration > 0 else 0.0
    state = float(STATE_CODES.get(str(status.get("state")), -1))
    return (("pzc_err", float(err)), ("pzc_state", state), ("pzc_prog", progress),
            ("pzc_mt", mt))


class GcsReporter:
    """STATUSTEXT and NAMED_VALUE_FLOAT to the ground station (a Sink; see the module doc)."""

    def __init__(self, mav: Any, rate_hz: float = GCS_REPORT_HZ,
                 clock: Callable[[], float] = time.monotonic):
        self.mav, self.clock = mav, clock
        self.period = 1.0 / rate_hz
        self.t0 = clock()
        self.next_values = self.t0
        self.err = 0.0
        self.status_of: Callable[[], dict[str, Any]] | None = None
        self.texts_sent = 0
        self.values_sent = 0
        self.last_state = ""
        self.turn = 0                     # the value sent next (idle sends one at a time)

    def watch(self, status_of: Callable[[], dict[str, Any]]) -> None:
        """Where the values come from (the runner's ``status``), once the runner exists."""
        self.status_of = status_of

    def say(self, severity: int, text: str) -> None:
        self.mav.statustext_send(severity, fit(text).encode("ascii"))
        self.texts_sent += 1

    def refused(self, text: str) -> None:
        """A request the companion turned down (a GCS command, a control request)."""
        self.say(WARNING, f"{PREFIX}refused: {text}")

    # --- Sink ---------------------------------------------------------------------------------
    def record(self, rec: LoopRecord) -> None:
        self.err = rec.err_pos

    def status(self, event: StatusEvent) -> None:
        said = statustext(event)
        if said is not None:
            self.say(*said)
        if event.kind == ev.STOPPED:
            self.send_values()          # the final state, at once

    def idle(self) -> None:
        """Called before each sleep of the loop: the next value when it is due. One value at a
        time, spread over the period: a burst of four ahead of a setpoint on a slow serial link
        delays the setpoint (seen: docs/benchmarks-log.md)."""
        now = self.clock()
        if now >= self.next_values:
            self.next_values = now + self.period / len(VALUE_NAMES)
            self.send_values(one=True)

    def send_values(self, one: bool = False) -> None:
        """The values (all of them, or with ``one`` the next in turn)."""
        if self.status_of is None:
            return
        status = self.status_of()
        state = str(status.get("state"))
        if state != self.last_state:
            # The states no life-cycle event announces (those keep the events' contract:
            # Zenoh, the CSV), seen here at the values' rate.
            self.last_state = state
            said = _STATE_TEXT.get(state)
            if said is not None:
                self.say(INFO, PREFIX + said.format(mode=status.get("track_mode", "")))
        ms = int((self.clock() - self.t0) * 1e3) & 0xFFFFFFFF
        named = values(status, self.err)
        if one:
            named = (named[self.turn % len(named)],)
            self.turn += 1
        for name, value in named:
            self.mav.named_value_float_send(ms, name.encode("ascii"), value)
            self.values_sent += 1

    def close(self) -> None:
        pass

    @property
    def linger(self) -> float:
        """Wall s the link should stay open (and read) after the run: the last text and values
        left just now, and an autopilot may drop a STATUSTEXT that arrives together with the
        TCP close (ArduPilot SITL did: docs/benchmarks-log.md). The rover is already stopped by
        then."""
        return LINGER_S if self.texts_sent else 0.0


class GcsCommands:
    """A GCS's MAV_CMD_DO_PAUSE_CONTINUE to the companion, as the loop's pause / resume."""

    def __init__(self, mav: Any, sysid: Callable[[], int], compid: int,
                 reporter: GcsReporter | None = None):
        self.mav, self.sysid, self.compid, self.reporter = mav, sysid, compid, reporter
        self.handled = 0

    def refused(self, text: str) -> None:
        """A control request (the Zenoh queryable) the loop turned down, for the GCS too."""
        if self.reporter is not None:
            self.reporter.refused(text)

    def for_us(self, msg: Any) -> bool:
        return (msg.command == MAV_CMD_DO_PAUSE_CONTINUE
                and msg.target_system in (0, self.sysid())
                and msg.target_component in (0, self.compid))

    def on_command(self, msg: Any, handle: Callable[[ControlRequest], None]) -> bool:
        """Handle a COMMAND_LONG / COMMAND_INT if it is ours (True), else leave it (False)."""
        if not self.for_us(msg):
            return False
        if msg.param1 not in (0.0, 1.0):           # NaN, or anything but pause / continue
            self.mav.command_ack_send(msg.command, MAV_RESULT_DENIED, 0, 0,
                                      msg.get_srcSystem(), msg.get_srcComponent())
            if self.reporter is not None:
                self.reporter.refused(f"DO_PAUSE_CONTINUE param1 {msg.param1!r}")
            return True
        verb = "pause" if msg.param1 == 0.0 else "resume"
        request = ControlRequest(verb, allow_path=False)
        handle(request)                # the loop answers at once (single thread)
        result = MAV_RESULT_ACCEPTED if request.ok else MAV_RESULT_TEMPORARILY_REJECTED
        self.mav.command_ack_send(msg.command, result, 0, 0, msg.get_srcSystem(),
                                  msg.get_srcComponent())
        if not request.ok and self.reporter is not None:
            self.reporter.refused(request.message)
        self.handled += 1
        return True


def attach(link: Any) -> tuple[GcsReporter, GcsCommands]:
    """The reporter and the command handler on ``link`` (a :class:`companion.live.link.Link`
    whose vehicle is known)."""
    reporter = GcsReporter(link.mav)
    commands = GcsCommands(link.mav, lambda: link.source_system, link.source_component,
                           reporter)
    return reporter, commands
