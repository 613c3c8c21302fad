"""ArduPilot Rover SITL for end-to-end tests: the real autopilot (ArduPilot's flight code built for
the host, with its own rover physics) as a process, a ground station on its second link, and the
companion pointed at it.

Where the autopilot is (first found wins):

* ``ARDUPILOT_SITL``: the ``ardurover`` binary; default parameters from ``ARDUPILOT_DEFAULTS``
  (comma-separated), else ``rover.parm`` (+ ``rover-skid.parm`` for the skid-steer model) next
  to the binary;
* ``ARDUPILOT_DIR``: an ArduPilot source tree, ``build/sitl/bin/ardurover`` and
  ``Tools/autotest/default_params/rover.parm`` (+ ``rover-skid.parm``).

With neither, :func:`sitl_paths` calls ``pytest.skip(SKIP_REASON)``; with a variable that names
no binary, ``pytest.fail`` (a misconfigured machine should not pass by skipping).

SITL's MAVLink ports for instance ``I`` (``-I I``): SERIAL0 on TCP ``5760 + 10 I``, SERIAL1 on
``5762 + 10 I``, SERIAL2 on ``5763 + 10 I``; it also binds UDP ``5501 + 10 I`` (RC input). It
opens nothing but SERIAL0 until a client connects there, and it boots only then. An instance
is chosen whose ports are free, under a lock file, so several can run side by side (also from
several pytest processes); 14550 is never among them. Each process runs in its own session
with its working directory (where it writes ``eeprom.bin``) in the test's temporary folder, and
is stopped by process group, SIGTERM then SIGKILL, on every way out: the fixture's finalizer,
``with`` blocks, an atexit hook, and (Linux) the parent-death signal if pytest itself dies.
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
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Callable, Iterator

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402

from companion_harness import ROOT, Companion  # noqa: E402,F401  (ROOT: the tests use it from here)

SKIP_REASON = ("ArduPilot SITL not configured: set ARDUPILOT_SITL (the ardurover binary) or "
               "ARDUPILOT_DIR (an ArduPilot tree with build/sitl/bin/ardurover)")
MANUAL, HOLD, GUIDED = 0, 4, 15          # ArduPilot Rover mode numbers (Rover/mode.h)
FORBIDDEN_PORT = 14550                   # a ground station's: never ours
MAX_INSTANCE = 63
LOCK_DIR = Path(tempfile.gettempdir())


# --------------------------------------------------------------------------- finding it

def sitl_paths(model: str = "rover-skid") -> tuple[Path, list[Path]]:
    """(ardurover binary, default parameter files) from the environment, or skip."""
    skid = model.startswith("rover-skid")
    names = ["rover.parm"] + (["rover-skid.parm"] if skid else [])
    binary_env, tree_env = os.environ.get("ARDUPILOT_SITL"), os.environ.get("ARDUPILOT_DIR")
    if binary_env:
        binary = Path(binary_env)
        defaults_env = os.environ.get("ARDUPILOT_DEFAULTS")
        defaults = ([Path(p) for p in defaults_env.split(",") if p] if defaults_env
                    else [binary.parent / n for n in names])
        source = "ARDUPILOT_SITL"
    elif tree_env:
        binary = Path(tree_env, "build", "sitl", "bin", "ardurover")
        defaults = [Path(tree_env, "Tools", "autotest", "default_params", n) for n in names]
        source = "ARDUPILOT_DIR"
    else:
        pytest.skip(SKIP_REASON)
    if not (binary.is_file() and os.access(binary, os.X_OK)):
        pytest.fail(f"{source}: {binary} is not an executable ardurover", pytrace=False)
    missing = [str(p) for p in defaults if not p.is_file()]
    if missing:
        pytest.fail(f"{source}: default parameter file(s) missing: {', '.join(missing)}",
                    pytrace=False)
    return binary, defaults


def ports_of(instance: int) -> dict[str, int]:
    base = 10 * instance
    return {"serial0": 5760 + base, "serial1": 5762 + base, "serial2": 5763 + base,
            "rc_in": 5501 + base}


def _port_free(port: int, kind: int) -> bool:
    with socket.socket(socket.AF_INET, kind) as s:
        if kind == socket.SOCK_STREAM:
            # as SITL binds it: TIME_WAIT leftovers of an earlier run do not block it
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def _instance_free(instance: int) -> bool:
    p = ports_of(instance)
    if FORBIDDEN_PORT in p.values():
        return False
    return (all(_port_free(p[k], socket.SOCK_STREAM) for k in ("serial0", "serial1", "serial2"))
            and _port_free(p["rc_in"], socket.SOCK_DGRAM))


class _InstanceLock:
    """An exclusive lock on one SITL instance number, across processes (flock)."""

    def __init__(self, instance: int):
        self.instance = instance
        self.path = LOCK_DIR / f"pzc-rover-ardupilot-sitl-I{instance}.lock"
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


def _claim_instance(skip: set[int]) -> _InstanceLock:
    for instance in range(MAX_INSTANCE + 1):
        if instance in skip:
            continue
        lock = _InstanceLock(instance)
        if not lock.acquire():
            continue
        if _instance_free(instance):
            return lock
        lock.release()
    raise RuntimeError(f"no free ArduPilot SITL instance in 0..{MAX_INSTANCE} (ports busy)")


def _die_with_parent() -> None:
    """In the child before exec: SIGTERM when the test process dies (Linux; best effort)."""
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG
    except Exception:  # noqa: BLE001
        pass


# --------------------------------------------------------------------------- the process

_LIVE: set["ArduPilotSITL"] = set()


@atexit.register
def _stop_all() -> None:
    for sitl in list(_LIVE):
        sitl.stop()


class ArduPilotSITL:
    """One ``ardurover`` process. ``params`` are written to a .parm file appended to
    ``--defaults`` (with ``wipe``, parameters start from the defaults every time); ``home``
    boots it elsewhere than SITL's default location (``--home lat,lon,alt,yaw``)."""

    def __init__(self, workdir: Path, *, speedup: float = 1.0, params: dict[str, float] | None
                 = None, model: str = "rover-skid", wipe: bool = True,
                 home: tuple[float, float, float, float] | None = None):
        self.binary, self.defaults = sitl_paths(model)
        self.workdir = Path(workdir)
        self.speedup, self.params, self.model, self.wipe = speedup, dict(params or {}), model, wipe
        self.home = home     # (lat, lon, alt m, yaw deg) to boot at; None: SITL's default (CMAC)
        self.proc: subprocess.Popen | None = None
        self.lock: _InstanceLock | None = None
        self.instance = -1
        self.log_path = self.workdir / "ardurover.log"
        self.started_at = 0.0

    # ports and connection strings
    @property
    def ports(self) -> dict[str, int]:
        return ports_of(self.instance)

    def url(self, serial: int = 0) -> str:
        return f"tcp:127.0.0.1:{self.ports[f'serial{serial}']}"

    def argv(self) -> list[str]:
        defaults = [str(p) for p in self.defaults]
        if self.params:
            extra = self.workdir / "extra.parm"
            extra.write_text("".join(f"{k} {v:g}\n" for k, v in self.params.items()))
            defaults.append(str(extra))
        return [str(self.binary), *(["-w"] if self.wipe else []), "--model", self.model,
                "--speedup", f"{self.speedup:g}", f"-I{self.instance}",
                *(["--home", ",".join(f"{v:.8f}" for v in self.home)] if self.home else []),
                "--defaults", ",".join(defaults)]

    def start(self, timeout: float = 10.0) -> "ArduPilotSITL":
        self.workdir.mkdir(parents=True, exist_ok=True)
        tried: set[int] = set()
        for _ in range(3):          # another program may take a port between check and bind
            self.lock = _claim_instance(tried)
            self.instance = self.lock.instance
            tried.add(self.instance)
            with open(self.log_path, "wb") as log:
                self.proc = subprocess.Popen(
                    self.argv(), cwd=self.workdir, stdin=subprocess.DEVNULL, stdout=log,
                    stderr=subprocess.STDOUT, start_new_session=True, preexec_fn=_die_with_parent)
            _LIVE.add(self)
            self.started_at = time.monotonic()
            if self._wait_listening(timeout):
                return self
            self.stop()
        raise RuntimeError(f"ardurover did not start listening:\n{self.log_tail()}")

    def _wait_listening(self, timeout: float) -> bool:
        """SERIAL0 is listening (SITL says so), without connecting (a client starts the boot)."""
        try:
            self.wait_log("Waiting for connection", timeout)
        except AssertionError:
            return False
        return True

    def wait_log(self, text: str, timeout: float) -> None:
        """Until SITL's own output contains ``text``; AssertionError if it dies or times out."""
        deadline, needle = time.monotonic() + timeout, text.encode()
        while needle not in self.log_path.read_bytes():
            if not self.alive():
                raise AssertionError(f"ardurover exited before saying {text!r}:\n{self.log_tail()}")
            if time.monotonic() > deadline:
                raise AssertionError(f"ardurover did not say {text!r} within {timeout:g} s:\n"
                                     f"{self.log_tail()}")
            time.sleep(0.02)

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def cpu_seconds(self) -> float:
        """CPU time (user + system) the running process has used so far."""
        fields = Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def stop(self, grace: float = 3.0) -> int | None:
        """SIGTERM to the process group, SIGKILL after ``grace`` s; the exit code."""
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
        _LIVE.discard(self)
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

    def __enter__(self) -> "ArduPilotSITL":
        return self.start() if self.proc is None else self

    def __exit__(self, *exc) -> None:
        self.stop()


@contextlib.contextmanager
def sitl_factory(workdir: Path) -> Iterator[Callable[..., ArduPilotSITL]]:
    """``start(speedup=..., params={...}, model=...)`` starts one more SITL in its own folder
    under ``workdir``; all are stopped when the block ends (whatever happens)."""
    started: list[ArduPilotSITL] = []
    sitl_paths()                         # skip before anything else happens

    def start(**kw: Any) -> ArduPilotSITL:
        sitl = ArduPilotSITL(Path(workdir) / f"ardupilot{len(started)}", **kw)
        started.append(sitl)
        return sitl.start()

    try:
        yield start
    finally:
        for sitl in started:
            sitl.stop()


# --------------------------------------------------------------------------- ground station

class GroundStation:
    """A pilot / ground station on another of the vehicle's links (SERIAL1 by default), for a
    ``with`` block: pymavlink over TCP, read continuously by a thread into ``seen`` (wall time,
    message) so nothing is missed while the test does other things. Only the vehicle's own
    heartbeats set ``mode`` / ``armed`` (ArduPilot forwards the companion's to this link too)."""

    def __init__(self, sitl: ArduPilotSITL, serial: int = 1, sysid: int = 255, compid: int = 190,
                 timeout: float = 15.0):
        if serial:   # SITL opens SERIAL1 and up once a client is on SERIAL0
            sitl.wait_log(f"SERIAL{serial} on TCP port", timeout)
        self.conn = mavutil.mavlink_connection(sitl.url(serial), source_system=sysid,
                                               source_component=compid, dialect="ardupilotmega")
        self.mav = self.conn.mav
        self.me = (sysid, compid)
        self.seen: list[tuple[float, Any]] = []
        self.mode: int | None = None
        self.armed = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def __enter__(self) -> "GroundStation":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        with contextlib.suppress(OSError):
            self.conn.close()

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
                    if msg.get_type() == "HEARTBEAT" and from_vehicle(msg):
                        self.mode = msg.custom_mode
                        self.armed = bool(msg.base_mode
                                          & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                    self.seen.append((time.monotonic(), msg))

    def messages(self, kind: str, after: float = 0.0, vehicle: bool = True) -> list[Any]:
        """Messages of ``kind`` that arrived after wall time ``after`` (the vehicle's only)."""
        with self._lock:
            return [m for w, m in self.seen if w >= after and m.get_type() == kind
                    and (not vehicle or from_vehicle(m))]

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

    def command(self, command: int, *params: float, timeout: float = 5.0) -> int:
        """COMMAND_LONG to the vehicle; the result of the COMMAND_ACK addressed to us."""
        p = list(params) + [0.0] * (7 - len(params))
        sent = time.monotonic()
        with self._lock:
            self.mav.command_long_send(1, 1, command, 0, *p)
        ack = self.wait_for("COMMAND_ACK", lambda m: m.command == command and (
            (m.target_system, m.target_component) in (self.me, (0, 0))), timeout, sent)
        return ack.result

    def set_mode(self, mode: int) -> int:
        """MAV_CMD_DO_SET_MODE (custom mode ``mode``): the ACK's result (0 accepted)."""
        return self.command(176, mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)

    def set_rate(self, msg_id: int, hz: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL on this link: the ACK's result."""
        return self.command(511, msg_id, 1e6 / hz)


def from_vehicle(msg: Any) -> bool:
    return msg.get_srcSystem() == 1 and msg.get_srcComponent() == 1


def ground_speed(msg: Any) -> float:
    """Horizontal speed of a LOCAL_POSITION_NED (m/s)."""
    return math.hypot(msg.vx, msg.vy)


# --------------------------------------------------------------------------- the companion

class CompanionProcess(Companion):
    """``python -m companion run --connect URL ARGS`` (SITL's TCP port) for a ``with`` block."""

    def __init__(self, url: str, *args: str):
        super().__init__(None, *args, url=url)


def circle_mission(path: Path, duration: float, radius: float = 3.0, speed: float = 1.0) -> Path:
    """A clockwise circle from the rover's start pose, within a stock skid-steer rover's limits
    (the shipped 40 Hz gains for its 1.2 rad/s speed loop)."""
    path.write_text(
        f'name = "sitl circle"\nframe = "start"\nduration = {duration:g}\n'
        f'[trajectory]\nkind = "circle"\ncenter = [0.0, {radius:g}]\nradius = {radius:g}\n'
        f'speed = {speed:g}\ndirection = "cw"\nstart_bearing_deg = 270.0\n'
        f'[limits]\nmax_speed = 2.0\nmax_yaw_rate = 1.5\n[vehicle]\nw_c = 1.2\n')
    return path
