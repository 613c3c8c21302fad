"""A null-modem cable between two pseudo-terminals, paced like a UART, for serial-link tests.

``PtyCable`` opens two pty pairs and copies bytes between their master sides in a thread; each
end's slave device (``/dev/pts/N``) is what a process opens as its serial port. With ``baud`` the
cable moves at most ``baud / 10`` bytes a second each way (8N1: ten bits a byte) and holds at most
``buffer`` bytes in flight per direction: what a UART cannot carry is dropped and counted, as on
a real wire whose receiver falls behind. The test keeps each slave open itself (raw mode, no echo)
so the ptys never hang up between the processes' opens and closes. ``stall()`` loses every byte
both ways until ``resume()`` (a telemetry radio's fade: the UARTs go on draining at their pace,
nothing queues, nothing blocks a writer); what it lost is counted in ``lost``.
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from collections import deque


class PtyCable:
    def __init__(self, baud: int | None = None, buffer: int = 4096):
        self.baud = baud
        self.buffer = buffer
        self._fds: list[int] = []
        self.masters: list[int] = []
        self.paths: list[str] = []
        for _ in range(2):
            master, slave = os.openpty()
            tty.setraw(slave)            # no echo and no line editing before a process opens it
            os.set_blocking(master, False)
            self._fds += [master, slave]
            self.masters.append(master)
            self.paths.append(os.ttyname(slave))
        self.carried = [0, 0]     # bytes delivered: [end 0 -> end 1, end 1 -> end 0]
        self.dropped = [0, 0]
        self.lost = [0, 0]        # bytes lost to a stall, per direction
        self.stalled = threading.Event()
        self._queues: list[deque] = [deque(), deque()]   # (due time, bytes) per direction
        self._free_at = [0.0, 0.0]                        # when the wire is idle again
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self.started = 0.0

    def __enter__(self) -> PtyCable:
        self.started = time.monotonic()
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.unplug()

    def unplug(self) -> None:
        """Cut the cable: both ptys hang up, as a USB serial device does when it vanishes
        (a process reading its end gets EIO)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        for fd in self._fds:
            os.close(fd)
        self._fds = []

    def stall(self) -> None:
        """Lose every byte both ways from now on (read and thrown away, as a fading radio
        does), and what is still on the wire."""
        self.stalled.set()

    def resume(self) -> None:
        self.stalled.clear()

    def _queued(self, direction: int) -> int:
        return sum(len(chunk) for _, chunk in self._queues[direction])

    def _take(self, direction: int, data: bytes, now: float) -> None:
        if self.baud is None:
            self._queues[direction].append((now, data))
            return
        room = self.buffer - self._queued(direction)
        if room < len(data):
            self.dropped[direction] += len(data) - max(room, 0)
            data = data[:max(room, 0)]
        if data:
            # The last byte leaves the wire once every byte before it has been clocked out.
            done = max(now, self._free_at[direction]) + len(data) * 10.0 / self.baud
            self._free_at[direction] = done
            self._queues[direction].append((done, data))

    def _deliver(self, direction: int, now: float) -> None:
        queue, out = self._queues[direction], self.masters[1 - direction]
        while queue and queue[0][0] <= now:
            _, chunk = queue.popleft()
            if self.stalled.is_set():
                self.lost[direction] += len(chunk)
                continue
            try:
                written = os.write(out, chunk)
            except BlockingIOError:
                written = 0          # the far end reads nothing: its tty buffer is full
            self.carried[direction] += written
            self.dropped[direction] += len(chunk) - written

    def _run(self) -> None:
        while not self._stop.is_set():
            now = time.monotonic()
            for direction in (0, 1):
                self._deliver(direction, now)
            due = [q[0][0] for q in self._queues if q]
            timeout = min([0.05] + [max(0.0, d - now) for d in due])
            ready, _, _ = select.select(self.masters, [], [], timeout)
            now = time.monotonic()
            for direction, master in enumerate(self.masters):
                if master in ready:
                    try:
                        data = os.read(master, 65536)
                    except (BlockingIOError, OSError):
                        continue
                    if self.stalled.is_set():
                        self.lost[direction] += len(data)
                        continue
                    self._take(direction, data, now)

    def rates(self) -> tuple[float, float]:
        """Average bytes per second carried each way since the cable was plugged in."""
        wall = max(time.monotonic() - self.started, 1e-9)
        return self.carried[0] / wall, self.carried[1] / wall
