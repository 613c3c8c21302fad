"""Test helpers for ``companion run`` end to end: the companion as an OS process, a recording
UDP proxy between plant and companion, a scripted fake vehicle, and short mission files.

Everything binds loopback ports chosen by the OS (port 0) and is stopped in ``__exit__``.
"""

from __future__ import annotations

import atexit
import json
import math
import os
import select
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink2  # noqa: E402

from sitl_plant.testing import free_udp_port  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
_LOGS: Path | None = None


# the commands that write flight logs, and the flags that say where (or that none is written)
_LOGGING = ("run", "demo", "identify", "calibrate")
_LOG_SAID = ("--log-dir", "--no-log", "--config", "--help", "-h", "--print-config")


def scratch_log_dir() -> Path:
    """A folder for the flight logs of runs whose test did not name one (never the checkout's
    ``logs/``), one per test process, removed when it exits (after every test has read them)."""
    global _LOGS
    if _LOGS is None:
        _LOGS = Path(tempfile.mkdtemp(prefix="pzc-test-logs-"))
        atexit.register(shutil.rmtree, _LOGS, True)
    return _LOGS


def with_log_dir(args: Sequence[str], folder: Path | None = None) -> list[str]:
    """``companion`` arguments with ``--log-dir`` added (``folder``, else the scratch folder)
    when the command writes flight logs and the test said nothing of where (a config file
    may say it; the default, ./logs, is the checkout's when run from it)."""
    args = list(args)
    if args[:1] and args[0] in _LOGGING and not any(a in _LOG_SAID for a in args):
        args += ["--log-dir", str(folder or scratch_log_dir())]
    return args


def companion_cli(*args: str, timeout: float, cwd: Path = ROOT, env: dict[str, str] | None = None,
                  prefix: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    """``python -m companion ARGS`` run to its end, output captured. ``timeout`` is each test
    file's guard against a hung run (it fails the test), not a speed target. Run from the
    checkout, its flight logs go to the scratch folder unless the test says where."""
    argv = with_log_dir(args) if Path(cwd) == ROOT else list(args)
    return subprocess.run([*prefix, sys.executable, "-m", "companion", *argv], capture_output=True,
                          text=True, timeout=timeout, cwd=cwd, env=env)


def ellipse_mission(path: Path, duration: float, f_r: float = 0.12) -> Path:
    path.write_text(f'name = "ellipse {duration:g} s"\nframe = "start"\nduration = {duration}\n'
                    f'[trajectory]\nkind = "ellipse"\nf_r = {f_r}\n')
    return path


class Companion:
    """``python -m companion run --connect udpin:127.0.0.1:PORT ARGS`` (or ``url=``) for a
    ``with`` block; killed on exit if still running.

    Two threads drain its stdout and stderr as it writes them, so a chatty run never blocks on
    a full pipe while the test waits on something else, and a failed wait can say what the run
    said so far (``said()``)."""

    def __init__(self, port: int | None, *args: str, command: str = "run",
                 url: str | None = None):
        self.argv = [sys.executable, "-m", "companion", *with_log_dir(
            [command, "--connect", url or f"udpin:127.0.0.1:{port}", *args])]
        self.proc: subprocess.Popen | None = None
        self.stdout = self.stderr = ""
        self._out: list[str] = []
        self._err: list[str] = []
        self._drains: list[threading.Thread] = []
        self.started_at = 0.0

    def __enter__(self) -> Companion:
        self.proc = subprocess.Popen(self.argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, cwd=ROOT)
        self.started_at = time.monotonic()
        self._drains = [threading.Thread(target=_drain, args=(pipe, into), daemon=True)
                        for pipe, into in ((self.proc.stdout, self._out),
                                           (self.proc.stderr, self._err))]
        for t in self._drains:
            t.start()
        return self

    def __exit__(self, *exc) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self._collect()

    def said(self) -> str:
        """What the run has written to stderr so far."""
        return "".join(self._err)

    def _collect(self) -> None:
        for t in self._drains:
            t.join(5.0)
        self.stdout, self.stderr = "".join(self._out), "".join(self._err)

    def wait_for_stderr(self, needle: str, timeout: float) -> None:
        """Wait until the run has said ``needle`` on stderr (what the run says, not a guess at
        how long it takes on a loaded machine)."""
        self.wait_until(lambda: needle in self.said(), timeout, f"{needle!r} said")

    def wait_until(self, predicate, timeout: float, what: str = "condition") -> None:
        """Wait for ``predicate()`` while the run is alive; if it ends or ``timeout`` passes
        first, fail with its exit code and what it said."""
        deadline = time.monotonic() + timeout
        while not predicate():
            code = self.proc.poll()
            if code is not None or time.monotonic() > deadline:
                if code is not None:
                    self._collect()
                raise AssertionError(f"{what}: not met within {timeout} s (companion "
                                     f"{'exited ' + str(code) if code is not None else 'running'})"
                                     f":\n{self.said()}")
            time.sleep(0.02)

    def wait_bound(self, port: int, timeout: float = 60.0) -> None:
        """Wait until the run has bound its ``udpin`` port (read from /proc/net/udp, so the
        check never takes the port from it). A plant started after this boots into a companion
        already listening, however long the companion took to import on a loaded machine."""
        local = f":{port:04X}"   # local_address, the second column: 0100007F:PORT in hex

        def bound() -> bool:
            with open("/proc/net/udp") as table:
                return any(line.split()[1].endswith(local) for line in list(table)[1:])
        self.wait_until(bound, timeout, f"udp port {port} bound")

    def wait(self, timeout: float) -> int:
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            self._collect()
            raise AssertionError(f"companion still running after {timeout} s:\n"
                                 f"{self.stderr}") from None
        self._collect()
        return self.proc.returncode

    def result(self) -> dict[str, Any]:
        lines = [line for line in self.stdout.splitlines() if line.startswith("{")]
        assert lines, f"no JSON result; stdout:\n{self.stdout}\nstderr:\n{self.stderr}"
        return json.loads(lines[-1])


def _drain(pipe, into: list[str]) -> None:
    for line in pipe:
        into.append(line)
    pipe.close()


def _parser():
    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = True
    return mav


@dataclass
class Seen:
    wall: float
    msg: Any


class Proxy:
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
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self.lock = threading.Lock()

    def __enter__(self) -> Proxy:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(2.0)
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


def is_zero(sp: Any) -> bool:
    return sp.vx == 0.0 and sp.vy == 0.0 and sp.yaw_rate == 0.0


def is_mode_command(msg: Any, mode: int) -> bool:
    return msg.command == 176 and int(msg.param2) == mode


# --------------------------------------------------------------------------- fake vehicle

@dataclass
class FakeVehicle:
    """A scripted ArduPilot-like rover for the companion, on pymavlink, in a thread.

    Answers SET_MESSAGE_INTERVAL, DO_SET_MODE and ARM with ACCEPTED, PARAM_REQUEST_READ with 0; streams ATTITUDE +
    LOCAL_POSITION_NED one tick at a time, going on when a setpoint answered the tick or after
    ``tick_timeout`` wall seconds. ``script(k, ms) -> dict`` can change tick k: keys ``x, vx``
    (LOCAL_POSITION_NED), ``yaw`` (ATTITUDE), ``ms`` (time_boot_ms), ``sysid`` (sender), or
    ``restart`` (reboot: back to MANUAL, disarmed), ``reboot`` (the same as a real autopilot does it:
    its clock from ``ms``, no heartbeat for ``reboot_gap`` s, then heartbeats only: nothing
    streamed until asked again; it answers MAV_CMD_REQUEST_MESSAGE for SYSTEM_TIME); the autopilot's own doings: ``ekf`` (an
    EKF_STATUS_REPORT with these flags), ``text`` (a STATUSTEXT), ``status`` (the heartbeat's
    system_status from now on), ``mode`` (it switches mode itself), ``silent`` (no pose this
    tick), ``attitude`` (False: a LOCAL_POSITION_NED without an ATTITUDE this tick); the link:
    ``deaf`` (nothing the companion sends arrives this tick: kept in ``lost``).
    Records every setpoint and command.
    """

    port: int
    script: Any = None
    start_ms: int = 100_000
    step_ms: int = 25
    tick_timeout: float = 0.02
    reboot_gap: float = 1.0
    setpoints: list[Any] = field(default_factory=list)
    commands: list[Any] = field(default_factory=list)
    sent_ms: list[tuple[int, str]] = field(default_factory=list)   # (time_boot_ms, note)
    lost: list[Any] = field(default_factory=list)     # what the companion sent while deaf

    def __post_init__(self):
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{self.port}", source_system=1,
                                               source_component=1, dialect="ardupilotmega")
        self.mode, self.armed, self.streaming = 0, False, False
        self.system_status = 4                   # MAV_STATE_ACTIVE
        self.deaf, self.ms, self.booting = False, self.start_ms, False
        self.rebooting_until = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> FakeVehicle:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.conn.close()

    def _heartbeat(self) -> None:
        if time.monotonic() < self.rebooting_until:
            return                               # rebooting: silent
        base = 1 | (128 if self.armed else 0) | (8 if self.mode == 15 else 0)
        self.conn.mav.heartbeat_send(10, 3, base, self.mode, self.system_status)

    def _handle(self, msg: Any) -> bool:
        """True when the message is a setpoint (it answers the tick)."""
        kind = msg.get_type()
        if time.monotonic() < self.rebooting_until:          # rebooting: hears nothing
            if kind == "COMMAND_LONG":
                self.commands.append(msg)
            return False
        if self.deaf:
            self.lost.append(msg)
            return False
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            self.setpoints.append(msg)
            return True
        if kind == "PARAM_REQUEST_READ":
            # as an autopilot answers (every parameter 0 here): run's preset look-up, without
            # which it would wait its read timeout while the script's ticks went by
            name = msg.param_id.encode() if isinstance(msg.param_id, str) else msg.param_id
            self.conn.mav.param_value_send(name, 0.0, 9, 1, 0)
            return False
        if kind == "COMMAND_LONG":
            self.commands.append(msg)
            if self.booting and msg.command in (176, 400):
                # a rebooted autopilot still starting: no mode change, no arming yet
                self.conn.mav.command_ack_send(msg.command, 4)        # MAV_RESULT_FAILED
                return False
            if msg.command == 511:
                self.streaming = True
            elif msg.command == 512 and int(msg.param1) == 2:     # SYSTEM_TIME, once
                self.conn.mav.system_time_send(0, self.ms)
            elif msg.command == 176:
                self.mode = int(msg.param2)
            elif msg.command == 400:
                self.armed = msg.param1 == 1.0
            self.conn.mav.command_ack_send(msg.command, 0)
            self._heartbeat()
        return False

    def _pump(self, timeout: float) -> bool:
        deadline, answered = time.monotonic() + timeout, False
        while not answered and (left := deadline - time.monotonic()) > 0:
            msg = self.conn.recv_match(blocking=True, timeout=min(left, 0.005))
            if msg is not None:
                answered = self._handle(msg) or answered
        return answered

    def _run(self) -> None:
        ms, k, next_hb = self.start_ms, 0, 0.0
        while not self._stop.is_set():
            if time.monotonic() >= next_hb:
                self._heartbeat()
                next_hb = time.monotonic() + 0.1
            if not self.streaming:
                self._pump(0.02)
                continue
            tick = {"x": 0.0, "y": 0.0, "vx": 0.0, "yaw": 0.0, "ms": ms, "sysid": 1}
            if self.script is not None:
                tick.update(self.script(k, ms) or {})
            if tick.get("restart") or tick.get("reboot"):
                ms = tick["ms"]
                tick["ms"] = ms
                self.mode, self.armed = 0, False
                if tick.get("reboot"):
                    self.streaming, self.ms, self.booting = False, ms, True
                    self.rebooting_until = time.monotonic() + self.reboot_gap
                    continue
            self.ms = tick["ms"]
            self.deaf = bool(tick.get("deaf"))
            mav = self.conn.mav
            if "status" in tick:
                self.system_status = tick["status"]
            if "text" in tick:                  # an autopilot says why before it acts
                mav.statustext_send(2, tick["text"].encode())
            if "mode" in tick:
                self.mode = tick["mode"]
            if "status" in tick or "mode" in tick:
                # heard at once: the script counts ticks, which pass as fast as the companion
                # answers, while the 10 Hz heartbeat counts wall time
                self._heartbeat()
            if "ekf" in tick:
                mav.ekf_status_report_send(tick["ekf"], 0.1, 0.1, 0.1, 0.1, 0.0)
            if tick.get("silent"):
                self._pump(self.tick_timeout)
                ms += self.step_ms
                k += 1
                continue
            mav.srcSystem = tick["sysid"]
            if tick.get("attitude", True):
                mav.attitude_send(tick["ms"], 0.0, 0.0, tick["yaw"], 0.0, 0.0, 0.0)
            mav.local_position_ned_send(tick["ms"], tick["x"], tick["y"], 0.0, tick["vx"],
                                        0.0, 0.0)
            mav.srcSystem = 1
            self.sent_ms.append((tick["ms"], tick.get("note", "")))
            self._pump(self.tick_timeout)
            ms += self.step_ms
            k += 1

    def answered(self, ms: int) -> int:
        return sum(1 for sp in self.setpoints if sp.time_boot_ms == ms)


def finite_setpoint(sp: Any) -> bool:
    return all(math.isfinite(v) for v in (sp.vx, sp.vy, sp.yaw_rate))
