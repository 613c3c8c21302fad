"""A recording UDP relay between a plant (or a fake vehicle) and the companion: every MAVLink
message both ways parsed and kept with the wall time it passed.
"""

from __future__ import annotations

import select
import socket
import threading
import time
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_plant.testing import free_udp_port

from .link_thread import LinkThread


def _parser():
    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = True
    return mav


@dataclass
class Seen:
    wall: float
    msg: Any


class Proxy(LinkThread):
    """UDP relay: the plant sends to ``plant_port``, the companion listens on ``companion_port``.

    Every message both ways is parsed and kept with the wall time it passed (``from_plant``,
    ``from_companion``). Run in a thread; stopped in ``__exit__``.
    """

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.plant_port = self.sock.getsockname()[1]
        self.companion_port = free_udp_port()
        self.companion_addr = ("127.0.0.1", self.companion_port)
        self.plant_addr: tuple[str, int] | None = None
        self.from_plant: list[Seen] = []
        self.from_companion: list[Seen] = []
        self._parse_plant, self._parse_companion = _parser(), _parser()
        self._prepare_thread()
        self.lock = threading.Lock()

    def _close(self) -> None:
        self.sock.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self.sock], [], [], 0.05)
            if not ready:
                continue
            data, addr = self.sock.recvfrom(65536)
            now = time.monotonic()
            if addr == self.companion_addr:
                if self.plant_addr is not None:
                    self.sock.sendto(data, self.plant_addr)
                msgs, out = self._parse_companion.parse_buffer(data) or [], self.from_companion
            else:
                self.plant_addr = addr
                self.sock.sendto(data, self.companion_addr)
                msgs, out = self._parse_plant.parse_buffer(data) or [], self.from_plant
            with self.lock:
                out.extend(Seen(now, m) for m in msgs if m.get_type() != "BAD_DATA")

    def companion_sent(self, kind: str, after: float = 0.0) -> list[Seen]:
        with self.lock:
            return [s for s in self.from_companion if s.msg.get_type() == kind and s.wall >= after]

    def plant_sent(self, kind: str, after: float = 0.0) -> list[Seen]:
        with self.lock:
            return [s for s in self.from_plant if s.msg.get_type() == kind and s.wall >= after]

    def wait_for(self, predicate, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return
            time.sleep(0.02)
        raise AssertionError(f"condition not met within {timeout} s")
