"""ArduPilot Rover SITL for end-to-end tests: the real autopilot (ArduPilot's flight code built for
the host, with its own rover physics) as a process, a ground station on its second link, and the
companion pointed at it.

Where the autopilot is (first found wins):

* ``ARDUPILOT_SITL``: the ``ardurover`` binary; default parameters from ``ARDUPILOT_DEFAULTS``
  (comma-separated; ``rover-skid.parm`` among them is left out for another model than
  ``rover-skid``), else ``rover.parm`` (+ ``rover-skid.parm`` for the skid-steer model) next
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

import contextlib
import os
import socket
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from pymavlink import mavutil

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

SKIP_REASON = ("ArduPilot SITL not configured: set ARDUPILOT_SITL (the ardurover binary) or "
               "ARDUPILOT_DIR (an ArduPilot tree with build/sitl/bin/ardurover)")
MANUAL, HOLD, GUIDED = 0, 4, 15          # ArduPilot Rover mode numbers (Rover/mode.h)
MAX_INSTANCE = 63
LOCK_PREFIX = "pzc-rover-ardupilot-sitl-I"      # LOCK_DIR/<prefix><instance>.lock


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
        if not skid:
            # ARDUPILOT_DEFAULTS names the skid-steer frame's file too: another model (the
            # Ackermann `rover`) boots on rover.parm alone, as ArduPilot's own tests do.
            defaults = [p for p in defaults if p.name != "rover-skid.parm"]
        source = "ARDUPILOT_SITL"
    elif tree_env:
        binary = Path(tree_env, "build", "sitl", "bin", "ardurover")
        defaults = [Path(tree_env, "Tools", "autotest", "default_params", n) for n in names]
        source = "ARDUPILOT_DIR"
    else:
        sitl.skip(SKIP_REASON)
    if not (binary.is_file() and os.access(binary, os.X_OK)):
        sitl.fail(f"{source}: {binary} is not an executable ardurover")
    missing = [str(p) for p in defaults if not p.is_file()]
    if missing:
        sitl.fail(f"{source}: default parameter file(s) missing: {', '.join(missing)}")
    return binary, defaults


def ports_of(instance: int) -> dict[str, int]:
    base = 10 * instance
    return {"serial0": 5760 + base, "serial1": 5762 + base, "serial2": 5763 + base,
            "rc_in": 5501 + base}


def _instance_free(instance: int) -> bool:
    p = ports_of(instance)
    if FORBIDDEN_PORT in p.values():
        return False
    return (all(port_free(p[k], socket.SOCK_STREAM) for k in ("serial0", "serial1", "serial2"))
            and port_free(p["rc_in"], socket.SOCK_DGRAM))


def _claim_instance(skip: set[int]) -> InstanceLock:
    return claim_instance(LOCK_PREFIX, MAX_INSTANCE, _instance_free, skip,
                          "ArduPilot SITL instance", "ports busy")


# --------------------------------------------------------------------------- the process

class ArduPilotSITL(SITLProcess):
    """One ``ardurover`` process. ``params`` are written to a .parm file appended to
    ``--defaults`` (with ``wipe``, parameters start from the defaults every time); ``home``
    boots it elsewhere than SITL's default location (``--home lat,lon,alt,yaw``)."""

    NAME, STOP_GRACE, LOG_POLL = "ardurover", 3.0, 0.02

    def __init__(self, workdir: Path, *, speedup: float = 1.0, params: dict[str, float] | None
                 = None, model: str = "rover-skid", wipe: bool = True,
                 home: tuple[float, float, float, float] | None = None):
        super().__init__(workdir, "ardurover.log")
        self.binary, self.defaults = sitl_paths(model)
        self.speedup, self.params, self.model, self.wipe = speedup, dict(params or {}), model, wipe
        self.home = home     # (lat, lon, alt m, yaw deg) to boot at; None: SITL's default (CMAC)

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

    def start(self, timeout: float = 10.0) -> ArduPilotSITL:
        self.workdir.mkdir(parents=True, exist_ok=True)
        # SERIAL0 is listening (SITL says so); nobody connects yet (a client starts the boot)
        if self._start_claimed(_claim_instance, lambda: self._spawn(self.argv(), self.workdir),
                               "Waiting for connection", timeout):
            return self
        raise RuntimeError(f"ardurover did not start listening:\n{self.log_tail()}")

    def cpu_seconds(self) -> float:
        """CPU time (user + system) the running process has used so far."""
        fields = Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@contextlib.contextmanager
def sitl_factory(workdir: Path) -> Iterator[Callable[..., ArduPilotSITL]]:
    """``start(speedup=..., params={...}, model=...)`` starts one more SITL in its own folder
    under ``workdir``; all are stopped when the block ends (whatever happens)."""
    sitl_paths()                         # skip before anything else happens
    with started_under(workdir, ArduPilotSITL, "ardupilot") as start:
        yield start


# --------------------------------------------------------------------------- ground station

class GroundStation(sitl.GroundStation):
    """A pilot / ground station on another of the vehicle's links (SERIAL1 by default), for a
    ``with`` block: pymavlink over TCP, read continuously by a thread into ``seen`` (wall time,
    message) so nothing is missed while the test does other things. Only the vehicle's own
    heartbeats set ``mode`` / ``armed`` (ArduPilot forwards the companion's to this link too)."""

    def __init__(self, sitl: ArduPilotSITL, serial: int = 1, sysid: int = 255, compid: int = 190,
                 timeout: float = 15.0):
        if serial:   # SITL opens SERIAL1 and up once a client is on SERIAL0
            sitl.wait_log(f"SERIAL{serial} on TCP port", timeout)
        super().__init__(sitl.url(serial), (1, 1), sysid, compid)

    def set_mode(self, mode: int) -> int:
        """MAV_CMD_DO_SET_MODE (custom mode ``mode``): the ACK's result (0 accepted)."""
        return self.command(176, mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)


def from_vehicle(msg: Any) -> bool:
    return msg.get_srcSystem() == 1 and msg.get_srcComponent() == 1


# --------------------------------------------------------------------------- the companion

class CompanionProcess(Companion):
    """``python -m companion run --connect URL ARGS`` (SITL's TCP port) for a ``with`` block."""

    def __init__(self, url: str, *args: str):
        super().__init__(None, *args, url=url)
