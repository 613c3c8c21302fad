"""A ground station for the tests: a pymavlink link of its own (system 255, component 190, as
QGroundControl / Mission Planner / MAVProxy are by default), reading in a thread and keeping
every message with its arrival time, and sending as a GCS does (commands, mission upload)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink import mavutil

from companion.mav import mission_transfer as mt
from companion.mission import geo

from .link_thread import LinkThread

COMPANION = 191


@dataclass
class Heard:
    wall: float
    msg: Any


class GroundStation(LinkThread):
    """``url`` (e.g. ``udpin:127.0.0.1:PORT`` or ``tcp:127.0.0.1:5762``) for a ``with`` block."""

    def __init__(self, url: str, sysid: int = 255, compid: int = 190):
        self.conn = mavutil.mavlink_connection(url, source_system=sysid, source_component=compid,
                                               dialect="ardupilotmega")
        self.mav = self.conn.mav
        self.heard: list[Heard] = []
        self.lock = threading.Lock()
        self._prepare_thread()
        self._paused = threading.Event()      # the reader steps aside (mission transfers)
        self._next_hb = 0.0

    def _run(self) -> None:
        while not self._stop.is_set():
            if self._paused.is_set():
                time.sleep(0.02)
                continue
            now = time.monotonic()
            if now >= self._next_hb:       # a GCS heart-beats at 1 Hz
                self._next_hb = now + 1.0
                try:
                    self.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS,
                                            mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                except OSError:
                    pass
            msg = self.conn.recv_match(blocking=True, timeout=0.05)
            if msg is not None and msg.get_type() != "BAD_DATA":
                with self.lock:
                    self.heard.append(Heard(time.monotonic(), msg))

    def of(self, kind: str, src: tuple[int, int] | None = None, after: float = 0.0) -> list[Any]:
        with self.lock:
            return [h.msg for h in self.heard if h.msg.get_type() == kind and h.wall >= after
                    and (src is None or (h.msg.get_srcSystem(), h.msg.get_srcComponent()) == src)]

    def texts(self, src: tuple[int, int] | None = None) -> list[str]:
        return [m.text for m in self.of("STATUSTEXT", src)]

    def wait_for(self, predicate: Callable[[], Any], timeout: float, what: str = "") -> Any:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = predicate()
            if value:
                return value
            time.sleep(0.02)
        raise AssertionError(f"{what or 'condition'} not met within {timeout} s; texts heard: "
                             f"{self.texts()}")

    def command(self, target: tuple[int, int], command: int, *params: float,
                timeout: float = 5.0) -> int:
        """COMMAND_LONG to (system, component); the COMMAND_ACK's result from it."""
        t0 = time.monotonic()
        p = list(params) + [0.0] * (7 - len(params))
        self.mav.command_long_send(target[0], target[1], command, 0, *p)
        acks = self.wait_for(lambda: [m for m in self.of("COMMAND_ACK", target, t0)
                                      if m.command == command], timeout,
                             f"COMMAND_ACK {command} from {target}")
        return acks[0].result

    def upload(self, sysid: int, items: list[Any]) -> None:
        """Upload a mission as a GCS does (the mission protocol; the reader steps aside)."""
        self._paused.set()
        time.sleep(0.1)
        try:
            mt.push(self.conn, sysid, 1, items)
        finally:
            self._paused.clear()


def waypoint_mission(home: tuple[float, float], points, speed: float) -> list[Any]:
    """A mission as a ground station uploads it: item 0 the home, a DO_CHANGE_SPEED to
    ``speed`` m/s, then a NAV_WAYPOINT at each (north, east) metres from ``home``."""
    out = [mt.item(0, 16, 0, (0.0, 0.0, 0.0, 0.0), int(round(home[0] * 1e7)),
                   int(round(home[1] * 1e7)), 0.0),
           mt.item(1, 178, 2, (1.0, speed, -1.0, 0.0), 0, 0, 0.0)]
    for north, east in points:
        lat, lon = geo.latlon_from_ne(north, east, home)
        out.append(mt.waypoint(len(out), lat, lon, 0.0))
    return out
