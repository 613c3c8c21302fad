"""PX4 SITL for end-to-end tests: PX4's flight code built for the host with SIH (its built-in
simulator) and the Ackermann rover airframe ``10045_sihsim_rover_ackermann``, a ground station on
its GCS link, and the companion on its offboard link.

Where PX4 is (first found wins):

* ``PX4_SITL``: the ``px4`` binary of a posix SITL build; its startup files are the ``etc``
  folder beside ``bin`` (a build's ``build/px4_sitl_default/{bin,etc}``, or the prebuilt
  ``px4sitl/{bin,etc}``);
* ``PX4_DIR``: a PX4-Autopilot tree with ``build/px4_sitl_default/bin/px4``.

With neither, :func:`px4_paths` calls ``pytest.skip(SKIP_REASON)``; with a variable that names no
binary, ``pytest.fail`` (a misconfigured machine should not pass by skipping).

Ports of instance ``N`` (``px4 -i N``; ``etc/init.d-posix/px4-rc.mavlink``), all UDP on
localhost: the offboard link listens on ``14580 + N`` and sends to ``14540 + N`` (the companion's
``udpin:0.0.0.0:14540+N``); the GCS link listens on ``18570 + N``; payload ``14280 + N`` ->
``14030 + N``, gimbal ``13030 + N`` -> ``13280 + N``, SIH display ``19450 + N`` -> ``19410 + N``.
Above N = 9 the offboard links of several instances share 14549, so N is 0..9. Stock PX4 sends the
GCS link to 14550, a real ground station's port: the harness runs PX4 on a copy of ``etc`` whose
``px4-rc.mavlink`` sends it instead to a port of the test's own (``gcs_port``), where the
:class:`GroundStation` listens. PX4 also takes a lock ``/tmp/px4_lock-N`` of its own.

PX4 writes its state in its working directory (``parameters.bson``, ``dataman``, ``eeprom/``,
``log/``): each process gets a fresh one under the test's temporary folder, so every run starts
from the airframe's defaults. Each runs in its own session and is stopped by process group,
SIGTERM then SIGKILL, on every way out: the fixture's finalizer, ``with`` blocks, an atexit hook,
and (Linux) the parent-death signal if pytest itself dies. PX4 runs in real time (250 Hz).
"""

from __future__ import annotations

import atexit
import contextlib
import errno
import fcntl
import os
import re
import select
import shutil
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

from companion_harness import Companion  # noqa: E402

SKIP_REASON = ("PX4 SITL not configured: set PX4_SITL (the px4 binary of a posix SITL build) or "
               "PX4_DIR (a PX4-Autopilot tree with build/px4_sitl_default/bin/px4)")
AIRFRAME = "sihsim_rover_ackermann"
# PX4 custom_mode words (main mode << 16 | sub mode << 24; px4_custom_mode.h)
MANUAL, POSCTL, OFFBOARD = 1 << 16, 3 << 16, 6 << 16
HOLD = (4 << 16) | (3 << 24)            # AUTO.LOITER: what a rover shows as "Hold"
FORBIDDEN_PORT = 14550                  # a ground station's: never ours
MAX_INSTANCE = 9
LOCK_DIR = Path(tempfile.gettempdir())
GCS_LINE = re.compile(r"^(mavlink start -x -u \$udp_gcs_port_local .*?)\s*$", re.M)


# --------------------------------------------------------------------------- finding it

def px4_paths() -> tuple[Path, Path]:
    """(px4 binary, its ``etc`` folder) from the environment, or skip."""
    binary_env, tree_env = os.environ.get("PX4_SITL"), os.environ.get("PX4_DIR")
    if binary_env:
        binary, source = Path(binary_env), "PX4_SITL"
    elif tree_env:
        binary, source = Path(tree_env, "build", "px4_sitl_default", "bin", "px4"), "PX4_DIR"
    else:
        pytest.skip(SKIP_REASON)
    if not (binary.is_file() and os.access(binary, os.X_OK)):
        pytest.fail(f"{source}: {binary} is not an executable px4", pytrace=False)
    etc = binary.resolve().parent.parent / "etc"
    airframes = etc / "init.d-posix" / "airframes"
    if not any(airframes.glob(f"*_{AIRFRAME}")):
        pytest.fail(f"{source}: no airframe {AIRFRAME} under {airframes} (PX4 main after July "
                    "2025 has it)", pytrace=False)
    return binary, etc


def ports_of(instance: int) -> dict[str, int]:
    n = instance
    return {"offboard_in": 14580 + n, "offboard_out": 14540 + n, "gcs_in": 18570 + n,
            "payload_in": 14280 + n, "payload_out": 14030 + n, "gimbal_in": 13030 + n,
            "gimbal_out": 13280 + n, "sih_in": 19450 + n, "sih_out": 19410 + n}


def _udp_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def _px4_lock_free(instance: int) -> bool:
    """PX4's own lock (``/tmp/px4_lock-N``, flock) is not held: no px4 -i N is running."""
    path = Path("/tmp") / f"px4_lock-{instance}"
    if not path.exists():
        return True
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        fcntl.flock(fd, fcntl.LOCK_UN)
        return True
    except OSError:
        return False
    finally:
        os.close(fd)


def _instance_free(instance: int) -> bool:
    p = ports_of(instance)
    return (FORBIDDEN_PORT not in p.values() and _px4_lock_free(instance)
            and all(_udp_free(port) for port in p.values()))


class _InstanceLock:
    """An exclusive lock on one PX4 instance number, across processes (flock)."""

    def __init__(self, instance: int):
        self.instance = instance
        self.path = LOCK_DIR / f"pzc-rover-px4-sitl-i{instance}.lock"
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
    raise RuntimeError(f"no free PX4 SITL instance in 0..{MAX_INSTANCE} (ports or locks busy)")


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _die_with_parent() -> None:
    """In the child before exec: SIGTERM when the test process dies (Linux; best effort)."""
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG
    except Exception:  # noqa: BLE001
        pass


def startup_files(etc: Path, dest: Path, gcs_port: int) -> Path:
    """A copy of PX4's ``etc`` whose GCS link sends to ``gcs_port`` instead of 14550."""
    shutil.copytree(etc, dest, symlinks=True)
    rc = dest / "init.d-posix" / "px4-rc.mavlink"
    text, n = GCS_LINE.subn(lambda m: f"{m.group(1)} -o {gcs_port}", rc.read_text(), count=1)
    if n != 1:
        raise RuntimeError(f"{rc}: no GCS 'mavlink start' line to redirect away from 14550")
    rc.write_text(text)
    return dest


# --------------------------------------------------------------------------- the process

_LIVE: set["PX4SITL"] = set()


@atexit.register
def _stop_all() -> None:
    for sitl in list(_LIVE):
        sitl.stop()


class PX4SITL:
    """One ``px4 -d`` process with the SIH Ackermann rover. ``params`` are set at start-up
    through PX4's ``PX4_PARAM_<NAME>`` environment variables (rcS applies them after the
    airframe's defaults)."""

    def __init__(self, workdir: Path, *, params: dict[str, float] | None = None):
        self.binary, self.etc = px4_paths()
        self.workdir = Path(workdir)
        self.params = dict(params or {})
        self.proc: subprocess.Popen | None = None
        self.lock: _InstanceLock | None = None
        self.instance = -1
        self.gcs_port = 0
        self.log_path = self.workdir / "px4.log"

    @property
    def ports(self) -> dict[str, int]:
        return {**ports_of(self.instance), "gcs_out": self.gcs_port}

    @property
    def sysid(self) -> int:
        return self.instance + 1            # rcS: MAV_SYS_ID = instance + 1

    def url(self) -> str:
        """The companion's connection string: the offboard link."""
        return f"udpin:127.0.0.1:{self.ports['offboard_out']}"

    def argv(self) -> list[str]:
        return [str(self.binary), "-d", str(self.workdir / "etc-copy"), "-i", str(self.instance),
                "-w", str(self.workdir / "rootfs")]

    def env(self) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if not k.startswith("PX4_PARAM_")}
        env.update(PX4_SIM_MODEL=AIRFRAME, PX4_SIMULATOR="sihsim")
        env.update({f"PX4_PARAM_{k}": f"{v:g}" for k, v in self.params.items()})
        return env

    def start(self, timeout: float = 30.0) -> "PX4SITL":
        tried: set[int] = set()
        for _ in range(3):          # another program may take a port between check and bind
            self.lock = _claim_instance(tried)
            self.instance = self.lock.instance
            tried.add(self.instance)
            shutil.rmtree(self.workdir, ignore_errors=True)      # parameters, dataman: fresh
            (self.workdir / "rootfs").mkdir(parents=True)
            self.gcs_port = _free_udp_port()
            startup_files(self.etc, self.workdir / "etc-copy", self.gcs_port)
            with open(self.log_path, "wb") as log:
                self.proc = subprocess.Popen(
                    self.argv(), cwd=self.workdir / "rootfs", env=self.env(),
                    stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                    start_new_session=True, preexec_fn=_die_with_parent)
            _LIVE.add(self)
            try:
                self.wait_log("Startup script returned successfully", timeout)
                return self
            except AssertionError:
                self.stop()
        raise RuntimeError(f"px4 did not start:\n{self.log_tail()}")

    def wait_log(self, text: str, timeout: float) -> None:
        """Until PX4's own output contains ``text``; AssertionError if it dies or times out."""
        deadline, needle = time.monotonic() + timeout, text.encode()
        while needle not in self.log_path.read_bytes():
            if not self.alive():
                raise AssertionError(f"px4 exited before saying {text!r}:\n{self.log_tail()}")
            if time.monotonic() > deadline:
                raise AssertionError(f"px4 did not say {text!r} within {timeout:g} s:\n"
                                     f"{self.log_tail()}")
            time.sleep(0.05)

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self, grace: float = 5.0) -> int | None:
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

    def __enter__(self) -> "PX4SITL":
        return self.start() if self.proc is None else self

    def __exit__(self, *exc) -> None:
        self.stop()


@contextlib.contextmanager
def px4_factory(workdir: Path) -> Iterator[Callable[..., PX4SITL]]:
    """``start(params={...})`` starts one more PX4 in its own folder under ``workdir``; all are
    stopped when the block ends (whatever happens)."""
    started: list[PX4SITL] = []
    px4_paths()                          # skip before anything else happens

    def start(**kw: Any) -> PX4SITL:
        sitl = PX4SITL(Path(workdir) / f"px4-{len(started)}", **kw)
        started.append(sitl)
        return sitl.start()

    try:
        yield start
    finally:
        for sitl in started:
            sitl.stop()


# --------------------------------------------------------------------------- ground station

class GroundStation:
    """A ground station on PX4's GCS link, for a ``with`` block: listens where the harness
    told PX4 to send (``gcs_port``) and answers to ``18570 + N``; read continuously by a thread
    into ``seen`` (wall time, message). Only the vehicle's own heartbeats set ``mode`` /
    ``armed``."""

    def __init__(self, sitl: PX4SITL, sysid: int = 255, compid: int = 190):
        self.sitl = sitl
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{sitl.gcs_port}",
                                               source_system=sysid, source_component=compid,
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

    def __enter__(self) -> "GroundStation":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        with contextlib.suppress(OSError):
            self.conn.close()

    def from_vehicle(self, msg: Any) -> bool:
        return msg.get_srcSystem() == self.sitl.sysid and msg.get_srcComponent() == 1

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
        with self._lock:
            return [m for w, m in self.seen if w >= after and m.get_type() == kind
                    and (not vehicle or self.from_vehicle(m))]

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
        return self.wait_for("HEARTBEAT", lambda m: m.custom_mode == mode, timeout, after)

    def command(self, command: int, *params: float, timeout: float = 5.0) -> int:
        """COMMAND_LONG to the vehicle; the result of the COMMAND_ACK addressed to us."""
        p = list(params) + [0.0] * (7 - len(params))
        sent = time.monotonic()
        with self._lock:
            self.mav.command_long_send(self.sitl.sysid, 1, command, 0, *p)
        ack = self.wait_for("COMMAND_ACK", lambda m: m.command == command and (
            (m.target_system, m.target_component) in (self.me, (0, 0))), timeout, sent)
        return ack.result

    def set_mode(self, custom_mode: int) -> int:
        """MAV_CMD_DO_SET_MODE with PX4's main / sub mode from a custom_mode word."""
        main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
        return self.command(176, mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub)

    def set_rate(self, msg_id: int, hz: float) -> int:
        return self.command(511, msg_id, 1e6 / hz)


# --------------------------------------------------------------------------- the companion

class CompanionProcess(Companion):
    """``python -m companion run --connect udpin:...:14540+N ARGS`` for a ``with`` block."""

    def __init__(self, sitl: PX4SITL, *args: str, command: str = "run"):
        super().__init__(None, *args, command=command, url=sitl.url())
