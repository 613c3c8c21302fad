"""``companion run`` / ``companion demo`` at the command line: help, and user errors as one line
with exit code 2 (never a traceback)."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from functools import partial

from sitl_plant.testing import free_udp_port
from testbed.process import ROOT, companion_cli

companion = partial(companion_cli, timeout=30.0)


def one_line_error(p: subprocess.CompletedProcess, prog: str, needle: str) -> None:
    assert p.returncode == 2, p.stderr
    assert "Traceback" not in p.stderr
    errors = [line for line in p.stderr.splitlines() if "error" in line]
    assert len(errors) == 1 and errors[0].startswith(f"companion {prog}: error:"), p.stderr
    assert needle in errors[0], errors[0]


def test_help():
    for cmd, needles in (("run", ("--connect", "--mission", "--stale-timeout", "exit codes")),
                         ("demo", ("--speedup", "--lockstep", "--out", "d_cen = 0.3"))):
        p = companion(cmd, "--help")
        assert p.returncode == 0
        assert all(n in p.stdout for n in needles), p.stdout


def test_missing_mission_file():
    one_line_error(companion("run", "--connect", f"udpin:127.0.0.1:{free_udp_port()}",
                             "--mission", "no/such/mission.toml"), "run", "no such file")


def test_missing_gains_file():
    one_line_error(companion("run", "--connect", f"udpin:127.0.0.1:{free_udp_port()}",
                             "--mission", "missions/circle.toml", "--gains", "nope.toml"),
                   "run", "nope.toml")


def test_no_vehicle_is_a_clear_error():
    p = companion("run", "--connect", f"udpin:127.0.0.1:{free_udp_port()}", "--mission",
                  "missions/circle.toml", "--heartbeat-timeout", "0.5")
    one_line_error(p, "run", "no heartbeat")


def test_unopenable_connection():
    one_line_error(companion("run", "--connect", "udpin:256.1.1.1:1", "--mission",
                             "missions/circle.toml"), "run", "cannot open")


def test_bad_flags():
    for flags in (("--rate", "-5"), ("--stale-timeout", "nan"), ("--max-speed", "0")):
        p = companion("run", "--mission", "missions/circle.toml", *flags)
        assert p.returncode == 2 and "Traceback" not in p.stderr
        assert p.stderr.strip().splitlines()[-1].startswith("companion run: error:")
    one_line_error(companion("demo", "--mission", "missing.toml"), "demo", "no such file")


def test_sigterm_while_waiting_for_a_vehicle_exits_at_once():
    proc = subprocess.Popen([sys.executable, "-m", "companion", "run", "--connect",
                             f"udpin:127.0.0.1:{free_udp_port()}", "--mission",
                             "missions/circle.toml"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        time.sleep(1.5)
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=5.0)
        assert time.monotonic() - t0 < 2.0
        assert proc.returncode != 0 and "Traceback" not in err, err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def test_no_pose_telemetry_is_a_clear_error():
    """A vehicle whose pose messages never arrive (dropout 1): exit 2, one line."""
    from sitl_plant.testing import PlantProcess
    with PlantProcess("--dropout", "1") as plant:
        p = companion("run", "--connect", f"udpin:127.0.0.1:{plant.port}", "--mission",
                      "missions/circle.toml", "--telemetry-timeout", "1")
    one_line_error(p, "run", "no valid pose telemetry within 1 s")
