"""Helpers for tests that drive a real ``sitl-plant`` process over real loopback UDP.

:class:`PlantProcess` starts ``python -m sitl_plant`` pushing to a free port and always kills it
on exit; :class:`Pilot` is a pymavlink ``udpin`` endpoint on that port acting as a ground station
or companion (mode, arm, rates, setpoints). Usable by any test in the project::

    with PlantProcess("--speedup", "5") as plant, Pilot(plant.port) as pilot:
        pilot.wait("HEARTBEAT")
        assert pilot.set_mode(15) == 0
"""

from __future__ import annotations

import math
import os
import random
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

MASK_SPEED_TURN_RATE = 1511   # 0x05E7: vx, vy, yaw_rate used (ArduPilot speed + turn rate)
MASK_VELOCITY = 3559          # vx, vy used
MASK_POSITION = 3580          # x, y used
FRAME_LOCAL_NED, FRAME_BODY_NED = 1, 8
GUIDED, HOLD, MANUAL = 15, 4, 0


def _ephemeral_low() -> int:
    """The lowest port the kernel hands out to sockets bound to port 0 (Linux default 32768)."""
    try:
        with open("/proc/sys/net/ipv4/ip_local_port_range") as f:
            return int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A loopback port free now, for a process about to bind it.

    Picked at random below the kernel's ephemeral range and checked by binding it: a port the
    kernel hands out (bind to 0) may be handed out again, to any implicit bind of any process,
    in the moment between this check and the real bind (tests in parallel workers start
    hundreds of such sockets), while nothing binds below that range unless it asks."""
    high = _ephemeral_low() - 1
    low = max(1024, high - 12000)
    for _ in range(200):
        port = random.randint(low, high)
        with socket.socket(socket.AF_INET, kind) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    with socket.socket(socket.AF_INET, kind) as s:      # crowded below: let the kernel pick
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_udp_port() -> int:
    return free_port(socket.SOCK_DGRAM)


class PlantProcess:
    """``python -m sitl_plant --connect udpout:127.0.0.1:PORT ARGS...`` for a ``with`` block."""

    def __init__(self, *args: str, port: int | None = None, sysid: int = 1):
        self.port = port or free_udp_port()
        self.sysid = sysid
        self.argv = [sys.executable, "-m", "sitl_plant", "--connect",
                     f"udpout:127.0.0.1:{self.port}", "--sysid", str(sysid), *args]
        self.proc: subprocess.Popen | None = None
        self.stderr = ""

    def __enter__(self) -> PlantProcess:
        self.proc = subprocess.Popen(self.argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                     text=True)
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def stop(self, sig: int | None = None, timeout: float = 5.0) -> int | None:
        """Signal the plant (SIGTERM by default), wait, kill if it hangs; its exit code."""
        proc = self.proc
        if proc is None:
            return None
        try:
            if proc.poll() is None:
                proc.send_signal(sig) if sig is not None else proc.terminate()
            try:
                _, self.stderr = proc.communicate(timeout=timeout)
            except subprocess.TimeoutExpired:
                proc.kill()
                _, self.stderr = proc.communicate()
        finally:
            self.proc = None
        return proc.returncode

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None


def _mavutil():
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil
    return mavutil


class Pilot:
    """A ground station / companion on ``udpin:127.0.0.1:PORT`` (or any ``url``) talking to one
    plant."""

    def __init__(self, port: int, target_system: int = 1, sysid: int = 255, compid: int = 190,
                 url: str | None = None):
        mavutil = _mavutil()
        self.conn = mavutil.mavlink_connection(url or f"udpin:127.0.0.1:{port}",
                                               source_system=sysid, source_component=compid,
                                               dialect="ardupilotmega")
        self.mav = self.conn.mav
        self.target_system = target_system
        self.texts: list[str] = []

    def __enter__(self) -> Pilot:
        return self

    def __exit__(self, *exc) -> None:
        self.conn.close()

    def _note(self, msg: Any) -> None:
        if msg is not None and msg.get_type() == "STATUSTEXT":
            self.texts.append(msg.text)

    def wait(self, kind: str, timeout: float = 5.0,
             cond: Callable[[Any], bool] | None = None) -> Any:
        """The next message of ``kind`` (that satisfies ``cond``); AssertionError on timeout."""
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            msg = self.conn.recv_match(blocking=True, timeout=min(left, 0.2))
            self._note(msg)
            if msg is not None and msg.get_type() == kind and (cond is None or cond(msg)):
                return msg
        raise AssertionError(f"no {kind} within {timeout} s")

    def collect(self, kinds: tuple[str, ...], seconds: float) -> list[Any]:
        """Every message of the given kinds arriving in the next ``seconds`` of wall time."""
        out, deadline = [], time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            msg = self.conn.recv_match(blocking=True, timeout=min(left, 0.2))
            self._note(msg)
            if msg is not None and msg.get_type() in kinds:
                out.append(msg)
        return out

    def stream(self, send: Callable[[], None], seconds: float, hz: float = 20.0,
               kinds: tuple[str, ...] = ("LOCAL_POSITION_NED",)) -> list[Any]:
        """Call ``send`` at ``hz`` (wall) for ``seconds``, collecting messages of ``kinds``."""
        out, deadline = [], time.monotonic() + seconds
        while time.monotonic() < deadline:
            send()
            out += self.collect(kinds, 1.0 / hz)
        return out

    def drain(self) -> None:
        while (msg := self.conn.recv_match(blocking=False)) is not None:
            self._note(msg)

    def command(self, command: int, *params: float, timeout: float = 5.0,
                target_system: int | None = None) -> int:
        """COMMAND_LONG; returns the COMMAND_ACK result."""
        p = list(params) + [0.0] * (7 - len(params))
        ts = self.target_system if target_system is None else target_system
        self.mav.command_long_send(ts, 1, command, 0, *p)
        return self.wait("COMMAND_ACK", timeout, lambda m: m.command == command).result

    def set_mode(self, mode: float, sub_mode: float = 0.0) -> int:
        return self.command(176, 1, mode, sub_mode)

    def arm(self, on: bool = True) -> int:
        return self.command(400, 1.0 if on else 0.0)

    def set_rate(self, msg_id: int, hz: float) -> int:
        return self.command(511, msg_id, 1e6 / hz if hz > 0 else hz)

    def setpoint(self, mask: int, frame: int = FRAME_BODY_NED, x: float = 0.0, y: float = 0.0,
                 vx: float = 0.0, vy: float = 0.0, yaw: float = 0.0, yaw_rate: float = 0.0,
                 target_system: int | None = None, afx: float = 0.0) -> None:
        ts = self.target_system if target_system is None else target_system
        self.mav.set_position_target_local_ned_send(0, ts, 1, frame, mask, x, y, 0.0, vx, vy, 0.0,
                                                    afx, 0.0, 0.0, yaw, yaw_rate)

    def speed_turn_rate(self, speed: float, yaw_rate: float) -> None:
        self.setpoint(MASK_SPEED_TURN_RATE, FRAME_BODY_NED, vx=speed, yaw_rate=yaw_rate)


def speed_of(msg: Any) -> float:
    """Ground speed from a LOCAL_POSITION_NED."""
    return math.hypot(msg.vx, msg.vy)
