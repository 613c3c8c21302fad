"""Faults for the field tests (issue 21): a TCP proxy that stalls or drops the companion's link,
and its UDP twin for PX4's offboard link (what is scored afterwards: :mod:`testbed.scoring`).

The proxy listens on a free loopback port and keeps one upstream connection to the autopilot
(opened with the first client, reused by the next: ArduPilot SITL's SERIAL0 serves one client).
``stall()`` stops reading both ways (a radio fade under TCP: what each side writes queues in the
kernel and arrives in a burst on ``resume()``); ``stall(TO_COMPANION)`` holds only what the
vehicle sends (the companion hears nothing, its setpoints still arrive), ``stall(TO_VEHICLE)``
only what the companion sends (it hears the vehicle, nothing of its own arrives); ``drop()``
closes the companion's connection as an autopilot that dropped it would, and accepts the next
one.
"""

from __future__ import annotations

import select
import socket
import threading

from .link_thread import LinkThread

BOTH, TO_COMPANION, TO_VEHICLE = "both", "to_companion", "to_vehicle"   # what a stall holds


class StallProxy:
    def __init__(self, upstream: tuple[str, int]):
        self.upstream_addr = upstream
        self.listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.listener.bind(("127.0.0.1", 0))
        self.listener.listen(2)
        self.port = self.listener.getsockname()[1]
        self.client: socket.socket | None = None
        self.upstream: socket.socket | None = None
        self.stalled = threading.Event()
        self.held = BOTH                      # which way(s) a stall holds
        self.clients = 0                      # connections accepted
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, daemon=True)

    @property
    def url(self) -> str:
        return f"tcp:127.0.0.1:{self.port}"

    def __enter__(self) -> StallProxy:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(2.0)
        for s in (self.client, self.upstream, self.listener):
            if s is not None:
                s.close()

    def stall(self, direction: str = BOTH) -> None:
        """Stop reading ``direction``: BOTH, TO_COMPANION (the vehicle's bytes) or TO_VEHICLE
        (the companion's bytes); what is held queues in the kernel until :meth:`resume`."""
        assert direction in (BOTH, TO_COMPANION, TO_VEHICLE), direction
        self.held = direction
        self.stalled.set()

    def resume(self) -> None:
        self.stalled.clear()

    def drop(self) -> None:
        """Close the companion's connection (the autopilot dropped it); the upstream stays."""
        with self._lock:
            if self.client is not None:
                self.client.close()
                self.client = None

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                socks = [self.listener] + [s for s in (self.client, self.upstream) if s]
            if self.stalled.is_set():
                # not read: the held side's bytes stay in the kernel (TCP's own back-pressure)
                held = {BOTH: (self.client, self.upstream), TO_COMPANION: (self.upstream,),
                        TO_VEHICLE: (self.client,)}[self.held]
                socks = [s for s in socks if s not in held]
            ready, _, _ = select.select(socks, [], [], 0.02)
            for s in ready:
                if s is self.listener:
                    conn, _ = s.accept()
                    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                    with self._lock:
                        if self.client is not None:
                            self.client.close()
                        self.client = conn
                        self.clients += 1
                        if self.upstream is None:
                            self.upstream = socket.create_connection(self.upstream_addr, 5.0)
                            self.upstream.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                    continue
                self._forward(s)

    def _forward(self, s: socket.socket) -> None:
        with self._lock:
            other = self.upstream if s is self.client else self.client
        try:
            data = s.recv(65536)
        except OSError:
            data = b""
        if not data:
            if s is self.client:
                with self._lock:
                    self.client = None
                s.close()
            return
        if other is not None:
            try:
                other.sendall(data)
            except OSError:
                pass


class UdpStallProxy(LinkThread):
    """A UDP relay that takes the autopilot's datagrams on ``listen_port`` (where it sends:
    PX4's offboard link 14540 + N) and passes them to the companion on ``companion_port``, and
    the companion's back to the autopilot's address. ``stall()`` drops everything both ways (a
    radio fade on UDP loses what is sent meanwhile); ``resume()`` passes again."""

    def __init__(self, listen_port: int, companion_port: int):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", listen_port))
        self.companion_addr = ("127.0.0.1", companion_port)
        self.autopilot_addr: tuple[str, int] | None = None
        self.stalled = threading.Event()
        self.dropped = 0
        self._prepare_thread()

    def _close(self) -> None:
        self.sock.close()

    def stall(self) -> None:
        self.stalled.set()

    def resume(self) -> None:
        self.stalled.clear()

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self.sock], [], [], 0.05)
            if not ready:
                continue
            try:
                data, addr = self.sock.recvfrom(65536)
            except OSError:
                continue
            if self.stalled.is_set():
                self.dropped += 1
                continue
            try:
                if addr == self.companion_addr:
                    if self.autopilot_addr is not None:
                        self.sock.sendto(data, self.autopilot_addr)
                else:
                    self.autopilot_addr = addr
                    self.sock.sendto(data, self.companion_addr)
            except OSError:
                pass
