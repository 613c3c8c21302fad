"""What the live loop tells the outside world, and how the outside world asks things of it.

The control loop (``companion run``) produces one :class:`LoopRecord` per control cycle and a
:class:`StatusEvent` at each life-cycle change, and hands both to every :class:`Sink` it was
given (flight-log CSV, Zenoh publisher, progress display, ...). Sinks are I/O at the edge: the
loop never knows what they do.

Requests from outside (Zenoh ``control`` queryable, ...) reach the loop through a
:class:`ControlChannel`: the requester calls :meth:`ControlChannel.submit` from any thread and
blocks for the answer; the loop calls :meth:`ControlChannel.poll` once per cycle, acts, and
answers each request with :meth:`ControlRequest.reply`. The loop stays single-threaded.
"""

from __future__ import annotations

import queue
import threading
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

# Life-cycle event kinds (StatusEvent.kind).
CONNECTED = "connected"
TRACKING = "tracking"
PAUSED = "paused"
RESUMED = "resumed"
MISSION_DONE = "mission_done"
FAILSAFE = "failsafe"
PILOT_OVERRIDE = "pilot_override"
AUTOPILOT_FAILSAFE = "autopilot_failsafe"   # the autopilot's own failsafe took the vehicle
STOPPED = "stopped"
MISSION_LOADED = "mission_loaded"
HANDED_BACK = "handed_back"          # --handover: a segment ended, AUTO drives again
GNSS = "gnss"                        # the receiver's class: the run's, said before moving; a drop


@dataclass(slots=True)
class LoopRecord:
    """One control cycle: vehicle time (s, from time_boot_ms), pose measured and filtered,
    reference, errors, the paper's u_p, and the setpoint sent (speed, yaw rate)."""

    vehicle_time: float
    mission_time: float
    x: float
    y: float
    yaw: float
    x_hat: float
    y_hat: float
    yaw_hat: float
    x_ref: float
    y_ref: float
    err_pos: float
    err_yaw: float
    ux: float
    uy: float
    speed_cmd: float
    yaw_rate_cmd: float
    mode: str
    armed: bool
    failsafe: str = ""

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(slots=True)
class StatusEvent:
    kind: str
    reason: str = ""
    vehicle_time: float | None = None
    detail: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


class Sink(Protocol):
    def record(self, rec: LoopRecord) -> None: ...
    def status(self, event: StatusEvent) -> None: ...
    def close(self) -> None: ...


@dataclass
class ControlRequest:
    verb: str
    payload: str = ""
    # A load-mission payload may name a file on this machine only for a local requester;
    # remote ones (the Zenoh queryable) always send mission text.
    allow_path: bool = True
    _done: threading.Event = field(default_factory=threading.Event, repr=False)
    ok: bool = False
    message: str = ""

    def reply(self, ok: bool, message: str) -> None:
        self.ok, self.message = ok, message
        self._done.set()


class ControlChannel:
    """Thread-safe hand-over of control requests to the single-threaded loop."""

    def __init__(self) -> None:
        self._queue: queue.Queue[ControlRequest] = queue.Queue()

    def submit(self, verb: str, payload: str = "", timeout: float = 2.0,
               allow_path: bool = True) -> tuple[bool, str]:
        """Called from any thread; blocks until the loop answers or ``timeout`` seconds pass."""
        request = ControlRequest(verb, payload, allow_path)
        self._queue.put(request)
        if not request._done.wait(timeout):
            return False, f"no answer from the control loop within {timeout:g} s"
        return request.ok, request.message

    def poll(self) -> list[ControlRequest]:
        """Called by the loop once per cycle: every request waiting, oldest first."""
        pending = []
        while True:
            try:
                pending.append(self._queue.get_nowait())
            except queue.Empty:
                return pending
