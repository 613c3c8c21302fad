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

import contextlib
import fcntl
import os
import re
import shutil
import socket
from collections.abc import Callable, Iterator
from pathlib import Path

from pymavlink import mavutil

from sitl_plant.testing import free_udp_port
from testbed import sitl
from testbed.process import Companion
from testbed.sitl import (
    FORBIDDEN_PORT,
    InstanceLock,
    SITLProcess,
    claim_instance,
    port_free,
    started_under,
)
from testbed.sitl import LIVE as _LIVE  # noqa: F401  (the harness's own tests read them here)
from testbed.sitl import stop_all as _stop_all  # noqa: F401

SKIP_REASON = ("PX4 SITL not configured: set PX4_SITL (the px4 binary of a posix SITL build) or "
               "PX4_DIR (a PX4-Autopilot tree with build/px4_sitl_default/bin/px4)")
AIRFRAME = "sihsim_rover_ackermann"
# PX4 custom_mode words (main mode << 16 | sub mode << 24; px4_custom_mode.h)
MANUAL, POSCTL, OFFBOARD = 1 << 16, 3 << 16, 6 << 16
HOLD = (4 << 16) | (3 << 24)            # AUTO.LOITER: what a rover shows as "Hold"
MAX_INSTANCE = 9
LOCK_PREFIX = "pzc-rover-px4-sitl-i"    # LOCK_DIR/<prefix><instance>.lock
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
        sitl.skip(SKIP_REASON)
    if not (binary.is_file() and os.access(binary, os.X_OK)):
        sitl.fail(f"{source}: {binary} is not an executable px4")
    etc = binary.resolve().parent.parent / "etc"
    airframes = etc / "init.d-posix" / "airframes"
    if not any(airframes.glob(f"*_{AIRFRAME}")):
        sitl.fail(f"{source}: no airframe {AIRFRAME} under {airframes} (PX4 main after July "
                  "2025 has it)")
    return binary, etc


def ports_of(instance: int) -> dict[str, int]:
    n = instance
    return {"offboard_in": 14580 + n, "offboard_out": 14540 + n, "gcs_in": 18570 + n,
            "payload_in": 14280 + n, "payload_out": 14030 + n, "gimbal_in": 13030 + n,
            "gimbal_out": 13280 + n, "sih_in": 19450 + n, "sih_out": 19410 + n}


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
            and all(port_free(port, socket.SOCK_DGRAM) for port in p.values()))


def _claim_instance(skip: set[int]) -> InstanceLock:
    return claim_instance(LOCK_PREFIX, MAX_INSTANCE, _instance_free, skip, "PX4 SITL instance",
                          "ports or locks busy")


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

class PX4SITL(SITLProcess):
    """One ``px4 -d`` process with the SIH Ackermann rover. ``params`` are set at start-up
    through PX4's ``PX4_PARAM_<NAME>`` environment variables (rcS applies them after the
    airframe's defaults)."""

    NAME, STOP_GRACE, LOG_POLL = "px4", 5.0, 0.05

    def __init__(self, workdir: Path, *, params: dict[str, float] | None = None):
        super().__init__(workdir, "px4.log")
        self.binary, self.etc = px4_paths()
        self.params = dict(params or {})
        self.gcs_port = 0

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

    def start(self, timeout: float = 30.0) -> PX4SITL:
        if self._start_claimed(_claim_instance, self._launch,
                               "Startup script returned successfully", timeout):
            return self
        raise RuntimeError(f"px4 did not start:\n{self.log_tail()}")

    def _launch(self) -> None:
        shutil.rmtree(self.workdir, ignore_errors=True)      # parameters, dataman: fresh
        (self.workdir / "rootfs").mkdir(parents=True)
        self.gcs_port = free_udp_port()
        startup_files(self.etc, self.workdir / "etc-copy", self.gcs_port)
        self._spawn(self.argv(), self.workdir / "rootfs", self.env())


@contextlib.contextmanager
def px4_factory(workdir: Path) -> Iterator[Callable[..., PX4SITL]]:
    """``start(params={...})`` starts one more PX4 in its own folder under ``workdir``; all are
    stopped when the block ends (whatever happens)."""
    px4_paths()                          # skip before anything else happens
    with started_under(workdir, PX4SITL, "px4-") as start:
        yield start


# --------------------------------------------------------------------------- ground station

class GroundStation(sitl.GroundStation):
    """A ground station on PX4's GCS link, for a ``with`` block: listens where the harness
    told PX4 to send (``gcs_port``) and answers to ``18570 + N``; read continuously by a thread
    into ``seen`` (wall time, message). Only the vehicle's own heartbeats set ``mode`` /
    ``armed``."""

    def __init__(self, sitl: PX4SITL, sysid: int = 255, compid: int = 190):
        self.sitl = sitl
        super().__init__(f"udpin:127.0.0.1:{sitl.gcs_port}", (sitl.sysid, 1), sysid, compid)

    def set_mode(self, custom_mode: int) -> int:
        """MAV_CMD_DO_SET_MODE with PX4's main / sub mode from a custom_mode word."""
        main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
        return self.command(176, mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub)


# --------------------------------------------------------------------------- the companion

class CompanionProcess(Companion):
    """``python -m companion run --connect udpin:...:14540+N ARGS`` for a ``with`` block."""

    def __init__(self, sitl: PX4SITL, *args: str, command: str = "run"):
        super().__init__(None, *args, command=command, url=sitl.url())
