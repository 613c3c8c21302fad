"""What the view knows of each rover on the bus, from ``rover/*/state`` and ``rover/*/status``.

Zenoh's callback threads call :meth:`Fleet.on_sample`, which decodes (``bus.codec.decode``) and keeps,
per vehicle: the path driven and the reference path seen so far (every state sample's pose and
reference, thinned to ``MAX_POINTS`` by dropping every other point when full, so an hours-long
flight stays a bounded line), the latest state sample, the last life-cycle event and failsafe,
and when the last message arrived. :meth:`Fleet.take` hands the drawing thread a copy of what
changed since its last call; a vehicle silent for longer than ``stale_after`` is stale.
Nothing here publishes: the view only subscribes.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..bus.codec import NOTICES, decode

MAX_POINTS = 4000          # per path: ~64 kB a redraw, thinned (never cut) when full


@dataclass
class Rover:
    vehicle_id: str
    driven: list[tuple[float, float]] = field(default_factory=list)     # (x north, y east)
    reference: list[tuple[float, float]] = field(default_factory=list)
    stride: int = 1                      # keep every stride-th sample (doubles when full)
    state: dict[str, Any] | None = None  # the latest state payload
    status: dict[str, Any] | None = None  # the latest status payload
    failsafe: str = ""                   # reason of the last failsafe, until tracking resumes
    events: list[dict[str, Any]] = field(default_factory=list)   # status payloads not drawn yet
    last_rx: float = 0.0                 # monotonic, this process
    state_msgs: int = 0
    bad: int = 0
    series: list[tuple[float, float, float, float]] = field(default_factory=list)
    _seen: int = 0

    def add_state(self, msg: dict[str, Any]) -> None:
        self.state = msg
        self.state_msgs += 1
        self._seen += 1
        # (sent_at, |error|, speed, yaw rate) of every sample, for the plots; bounded when the
        # drawing thread falls behind
        t, err, sp = msg.get("sent_at"), msg.get("error") or {}, msg.get("setpoint") or {}
        if isinstance(t, (int, float)) and len(self.series) < MAX_POINTS:
            self.series.append((float(t), _num(err.get("position")), _num(sp.get("speed")),
                                _num(sp.get("yaw_rate"))))
        if (self._seen - 1) % self.stride:
            return
        for points, key in ((self.driven, "pose"), (self.reference, "reference")):
            p = msg.get(key) or {}
            x, y = p.get("x"), p.get("y")
            if isinstance(x, (int, float)) and isinstance(y, (int, float)):
                points.append((float(x), float(y)))
        if len(self.driven) > MAX_POINTS or len(self.reference) > MAX_POINTS:
            self.driven[:] = self.driven[::2]
            self.reference[:] = self.reference[::2]
            self.stride *= 2

    def add_status(self, msg: dict[str, Any]) -> None:
        self.events.append(msg)          # (notices too: drawn in the event log)
        if msg.get("kind") in NOTICES:
            return
        self.status = msg
        kind = msg.get("kind")
        if kind == "failsafe":
            self.failsafe = str(msg.get("reason", ""))
        elif kind in ("tracking", "resumed", "connected"):
            self.failsafe = ""

    @property
    def phase(self) -> str:
        """The life-cycle word to show: the last event's kind, 'tracking' once state flows."""
        kind = (self.status or {}).get("kind", "")
        if self.state is not None and kind in ("", "connected", "mission_loaded"):
            return "tracking"
        return kind or "seen"


@dataclass
class Snapshot:
    """A copy of one rover for the drawing thread."""

    vehicle_id: str
    driven: list[tuple[float, float]]
    reference: list[tuple[float, float]]
    state: dict[str, Any] | None
    phase: str
    failsafe: str
    events: list[dict[str, Any]]
    age: float                          # s since its last message
    stale: bool
    state_msgs: int
    series: list[tuple[float, float, float, float]]


class Fleet:
    def __init__(self, stale_after: float = 2.0, clock: Callable[[], float] = time.monotonic):
        self.stale_after = stale_after
        self.clock = clock
        self.lock = threading.Lock()
        self.rovers: dict[str, Rover] = {}
        self.samples = 0
        self.bad = 0

    def on_sample(self, sample: Any) -> None:
        """Zenoh's thread: one state or status sample."""
        self.add(str(sample.key_expr), sample.payload.to_bytes())

    def add(self, key: str, data: bytes) -> None:
        parts = key.split("/")
        with self.lock:
            self.samples += 1
            if len(parts) != 3 or parts[2] not in ("state", "status"):
                self.bad += 1
                return
            vid, kind = parts[1], parts[2]
            rover = self.rovers.get(vid) or self.rovers.setdefault(vid, Rover(vid))
            try:
                msg = decode(data, kind)
            except ValueError:
                rover.bad += 1
                return
            rover.last_rx = self.clock()
            (rover.add_state if kind == "state" else rover.add_status)(msg)

    def take(self) -> list[Snapshot]:
        """Every rover as it is now (the events since the last take handed over once)."""
        now = self.clock()
        out = []
        with self.lock:
            for vid in sorted(self.rovers):
                r = self.rovers[vid]
                age = now - r.last_rx if r.last_rx else float("inf")
                out.append(Snapshot(vid, list(r.driven), list(r.reference), r.state, r.phase,
                                    r.failsafe, r.events, age, age > self.stale_after,
                                    r.state_msgs, r.series))
                r.events, r.series = [], []
        return out


def _num(v: Any) -> float:
    return float(v) if isinstance(v, (int, float)) else float("nan")
