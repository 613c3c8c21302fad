"""What the two SITL harnesses (:mod:`testbed.ardupilot`, :mod:`testbed.px4`) share: skipping
or failing a test when the machine has no usable SITL, the lock that claims one instance number
across processes, the process that runs in its own session and is stopped by process group on
every way out (``with`` blocks, the factories, an atexit hook, the parent-death signal), and the
ground station that reads the vehicle's link in a thread.

What differs between the autopilots stays in each harness: where the binary is, the ports of an
instance and how to tell they are free (PX4 also has a lock of its own), the working folder and
command line, the text that says it is up, the vehicle's system id and the mode numbering.
"""

from __future__ import annotations

import atexit
import contextlib
import errno
import fcntl
import math
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NoReturn, TypeVar

from pymavlink import mavutil

from testbed.process import ROOT

FORBIDDEN_PORT = 14550                   # a ground station's: never ours
LOCK_DIR = Path(tempfile.gettempdir())
COMPANION_COMPID = 191                   # MAV_COMP_ID_ONBOARD_COMPUTER: the companion's frames


# --------------------------------------------------------------------------- finding it

def skip(reason: str) -> NoReturn:
    """No such SITL on this machine: the test is skipped (pytest's skip, imported only here, so a
    benchmark imports the test bed without pytest's help and stops on the same exception)."""
    import pytest
    pytest.skip(reason)


def fail(reason: str) -> NoReturn:
    """A SITL named but not usable: the test fails in one line (a misconfigured machine should
    not pass by skipping)."""
    import pytest
    pytest.fail(reason, pytrace=False)


# --------------------------------------------------------------------------- claiming an instance

def port_free(port: int, kind: int = socket.SOCK_DGRAM) -> bool:
    """Nobody has ``port`` bound (on any address), TCP or UDP as ``kind`` says."""
    with socket.socket(socket.AF_INET, kind) as s:
        if kind == socket.SOCK_STREAM:
            # as SITL binds it: TIME_WAIT leftovers of an earlier run do not block it
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


class InstanceLock:
    """An exclusive lock on one SITL instance number, across processes (flock on
    ``LOCK_DIR/<name_prefix><instance>.lock``)."""

    def __init__(self, name_prefix: str, instance: int):
        self.instance = instance
        self.path = LOCK_DIR / f"{name_prefix}{instance}.lock"
        self.fd: int | None = None

    def acquire(self) -> bool:
        fd = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.EAGAIN, errno.EACCES):
                return False
            raise
        self.fd = fd
        return True

    def release(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


def claim_instance(name_prefix: str, max_instance: int, is_free: Callable[[int], bool],
                   skip: set[int], what: str, busy: str) -> InstanceLock:
    """The lock of the first instance in 0..``max_instance`` (not in ``skip``) that nobody else
    holds and that ``is_free`` says is usable; RuntimeError naming ``what`` and what may be
    ``busy`` if there is none."""
    for instance in range(max_instance + 1):
        if instance in skip:
            continue
        lock = InstanceLock(name_prefix, instance)
        if not lock.acquire():
            continue
        if is_free(instance):
            return lock
        lock.release()
    raise RuntimeError(f"no free {what} in 0..{max_instance} ({busy})")


def die_with_parent() -> None:
    """In the child before exec: SIGTERM when the test process dies (Linux; best effort)."""
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG
    except Exception:  # noqa: BLE001
        pass


# --------------------------------------------------------------------------- the process

LIVE: set[SITLProcess] = set()         # every SITL started and not yet stopped, of either kind


@atexit.register
def stop_all() -> None:
    for sitl in list(LIVE):
        sitl.stop()


class SITLProcess:
    """One autopilot process writing its output to ``log_path``, run in its own session (so
    ``stop`` reaches its children by process group) and registered in ``LIVE`` while it runs.
    A subclass says what its output is called (``NAME``), how long ``stop`` waits
    (``STOP_GRACE``) and how often ``wait_log`` looks (``LOG_POLL``), and starts it with
    :meth:`_start_claimed`."""

    NAME = "sitl"
    STOP_GRACE = 3.0
    LOG_POLL = 0.02

    def __init__(self, workdir: Path, log_name: str):
        self.workdir = Path(workdir)
        self.proc: subprocess.Popen | None = None
        self.lock: InstanceLock | None = None
        self.instance = -1
        self.log_path = self.workdir / log_name
        self.started_at = 0.0

    def start(self, timeout: float) -> SITLProcess:
        raise NotImplementedError

    def _start_claimed(self, claim: Callable[[set[int]], InstanceLock], launch: Callable[[], None],
                       ready_text: str, timeout: float) -> bool:
        """Claim an instance, ``launch`` it (which calls :meth:`_spawn`), wait until its output
        says ``ready_text``; up to three instances. False if none came up."""
        tried: set[int] = set()
        for _ in range(3):          # another program may take a port between check and bind
            self.lock = claim(tried)
            self.instance = self.lock.instance
            tried.add(self.instance)
            launch()
            try:
                self.wait_log(ready_text, timeout)
                return True
            except AssertionError:
                self.stop()
        return False

    def _spawn(self, argv: list[str], cwd: Path, env: dict[str, str] | None = None) -> None:
        with open(self.log_path, "wb") as log:
            self.proc = subprocess.Popen(
                argv, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=log,
                stderr=subprocess.STDOUT, start_new_session=True, preexec_fn=die_with_parent)
        LIVE.add(self)
        self.started_at = time.monotonic()

    def wait_log(self, text: str, timeout: float) -> None:
        """Until the process's own output contains ``text``; AssertionError if it dies or times
        out."""
        deadline, needle = time.monotonic() + timeout, text.encode()
        while needle not in self.log_path.read_bytes():
            if not self.alive():
                raise AssertionError(f"{self.NAME} exited before saying {text!r}:\n"
                                     f"{self.log_tail()}")
            if time.monotonic() > deadline:
                raise AssertionError(f"{self.NAME} did not say {text!r} within {timeout:g} s:\n"
                                     f"{self.log_tail()}")
            time.sleep(self.LOG_POLL)

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self, grace: float | None = None) -> int | None:
        """SIGTERM to the process group, SIGKILL after ``grace`` s (default ``STOP_GRACE``);
        the exit code."""
        grace = self.STOP_GRACE if grace is None else grace
        proc, code = self.proc, None
        if proc is not None:
            if proc.poll() is None:      # not yet reaped: its pid (= group id) is still its own
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGTERM)
            try:
                code = proc.wait(grace)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                code = proc.wait()
            self.proc = None
        LIVE.discard(self)
        if self.lock is not None:
            self.lock.release()
            self.lock = None
        return code

    def log_tail(self, lines: int = 30) -> str:
        try:
            text = self.log_path.read_text(errors="replace")
        except OSError:
            return ""
        return "\n".join(text.splitlines()[-lines:])

    def __enter__(self):
        return self.start() if self.proc is None else self

    def __exit__(self, *exc) -> None:
        self.stop()


P = TypeVar("P", bound=SITLProcess)


@contextlib.contextmanager
def started_under(workdir: Path, make: Callable[..., P], folder: str
                  ) -> Iterator[Callable[..., P]]:
    """``start(**kw)`` makes ``make(workdir/<folder><n>, **kw)`` and starts it; all are stopped
    when the block ends (whatever happens)."""
    started: list[P] = []

    def start(**kw: Any) -> P:
        sitl = make(Path(workdir) / f"{folder}{len(started)}", **kw)
        started.append(sitl)
        return sitl.start()

    try:
        yield start
    finally:
        for sitl in started:
            sitl.stop()


# --------------------------------------------------------------------------- ground station

class GroundStation:
    """A ground station on one of the vehicle's links (``url``), for a ``with`` block: pymavlink,
    read continuously by a thread into ``seen`` (wall time, message) so nothing is missed while
    the test does other things. Only the vehicle's own heartbeats (from ``vehicle``, a (system,
    component) pair) set ``mode`` / ``armed``; commands go to it."""

    def __init__(self, url: str, vehicle: tuple[int, int], sysid: int = 255, compid: int = 190):
        self.vehicle = vehicle
        self.conn = mavutil.mavlink_connection(url, source_system=sysid, source_component=compid,
                                               dialect="ardupilotmega")
        self.mav = self.conn.mav
        self.me = (sysid, compid)
        self.seen: list[tuple[float, Any]] = []
        self.mode: int | None = None
        self.armed = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        with contextlib.suppress(OSError):
            self.conn.close()

    def from_vehicle(self, msg: Any) -> bool:
        return (msg.get_srcSystem(), msg.get_srcComponent()) == self.vehicle

    def _read(self) -> None:
        fd = self.conn.port.fileno()
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([fd], [], [], 0.05)
            except (OSError, ValueError):
                return
            if not ready:
                continue
            with self._lock:
                while (msg := self.conn.recv_msg()) is not None:
                    if msg.get_type() == "BAD_DATA":
                        continue
                    if msg.get_type() == "HEARTBEAT" and self.from_vehicle(msg):
                        self.mode = msg.custom_mode
                        self.armed = bool(msg.base_mode
                                          & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                    self.seen.append((time.monotonic(), msg))

    def messages(self, kind: str, after: float = 0.0, vehicle: bool = True) -> list[Any]:
        """Messages of ``kind`` that arrived after wall time ``after`` (the vehicle's only)."""
        with self._lock:
            return [m for w, m in self.seen if w >= after and m.get_type() == kind
                    and (not vehicle or self.from_vehicle(m))]

    def arrival(self, msg: Any) -> float:
        """The wall time (time.monotonic) at which ``msg``, a message this station saw, came."""
        with self._lock:
            return next(w for w, m in self.seen if m is msg)

    def wait_for(self, kind: str, cond: Callable[[Any], bool] = lambda m: True,
                 timeout: float = 10.0, after: float | None = None) -> Any:
        """The first vehicle message of ``kind`` meeting ``cond`` that arrived after ``after``
        (default: now); AssertionError on timeout."""
        after = time.monotonic() if after is None else after
        deadline = time.monotonic() + timeout
        while True:
            for m in self.messages(kind, after):
                if cond(m):
                    return m
            if time.monotonic() > deadline:
                raise AssertionError(f"no {kind} as wanted within {timeout:g} s")
            time.sleep(0.02)

    def wait_mode(self, mode: int, timeout: float = 10.0, after: float | None = None) -> Any:
        """The vehicle's first HEARTBEAT in ``mode`` (since ``after``, default now)."""
        return self.wait_for("HEARTBEAT", lambda m: m.custom_mode == mode, timeout, after)

    def command(self, command: int, *params: float, timeout: float = 5.0,
                attempts: int = 3) -> int:
        """COMMAND_LONG to the vehicle; the result of the COMMAND_ACK addressed to us. Sent
        again (confirmation 1, 2, ...) after ``timeout`` s without an answer, as a ground
        station does (MAVLink's command protocol): a SITL's first command on a link it had
        just accepted once went unanswered for 5 s (make sitl-test, nothing beside it)."""
        p = list(params) + [0.0] * (7 - len(params))
        sent = time.monotonic()

        def ours(m: Any) -> bool:
            return m.command == command and (
                (m.target_system, m.target_component) in (self.me, (0, 0)))

        for confirmation in range(attempts):
            with self._lock:
                self.mav.command_long_send(*self.vehicle, command, confirmation, *p)
            with contextlib.suppress(AssertionError):      # no answer yet: send it again
                return self.wait_for("COMMAND_ACK", ours, timeout, sent).result
        raise AssertionError(f"no COMMAND_ACK for command {command} in {attempts} attempts "
                             f"of {timeout:g} s")

    def set_rate(self, msg_id: int, hz: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL on this link: the ACK's result."""
        return self.command(511, msg_id, 1e6 / hz)


# --------------------------------------------------------------------------- for the tests

def ground_speed(msg: Any) -> float:
    """Horizontal speed of a LOCAL_POSITION_NED (m/s)."""
    return math.hypot(msg.vx, msg.vy)


def sent_by_companion(frames: list[tuple[float, Any]],
                      kinds: tuple[str, ...] = ("SET_POSITION_TARGET_LOCAL_NED", "COMMAND_LONG")
                      ) -> list[tuple[int, Any]]:
    """(index, message) of the companion's frames of ``kinds`` in a tlog's ``frames``."""
    return [(i, m) for i, (_, m) in enumerate(frames)
            if m.get_srcComponent() == COMPANION_COMPID and m.get_type() in kinds]


def process_gone(pid: int, timeout: float) -> bool:
    """``pid`` has exited (or is a zombie) within ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            state = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0]
        except FileNotFoundError:
            return True
        if state == "Z":        # exited, not yet reaped by its new parent
            return True
        time.sleep(0.05)
    return False


def started_by_a_dying_process(module: str, cls: str, workdir: Path, timeout: float) -> int:
    """The pid of a ``module.cls(workdir).start()`` run by a Python process that then dies at
    once (``os._exit``: no finalizer, no atexit); only the parent-death signal can stop it."""
    code = ("import os, sys; from pathlib import Path; "
            f"import {module} as h; s = h.{cls}(Path(sys.argv[1])).start(); "
            "print(s.proc.pid, flush=True); os._exit(1)")
    out = subprocess.run([sys.executable, "-c", code, str(workdir)], capture_output=True,
                         text=True, timeout=timeout, cwd=ROOT, env={**os.environ})
    return int(out.stdout.split()[0])
