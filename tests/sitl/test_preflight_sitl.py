"""``companion preflight`` against the real autopilot: ArduPilot Rover SITL (``rover-skid``,
stock parameters), skipped unless ARDUPILOT_SITL or ARDUPILOT_DIR is set
(``testbed/ardupilot.py``).

Right after boot the EKF has no origin and the pre-arm checks fail; once it runs, a stock
skid-steer rover passes everything but the GCS failsafe (FS_GCS_ENABLE 0) and signing; ``--fix
--yes`` turns the failsafe on, reads it back, and a ground station on another link reads the
same value from the vehicle.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

from testbed.ardupilot import GroundStation
from testbed.process import ROOT

SPEEDUP = 2           # slow enough that the first preflight ends before the EKF has an origin
READY_WALL = 120.0 / SPEEDUP + 30.0      # wall s until the EKF has an origin and can arm
ESTIMATE = ("GPS_GLOBAL_ORIGIN", "EKF_STATUS_REPORT", "SYS_STATUS pre-arm")


def preflight(url: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "companion", "preflight", "--connect", url,
                           "--json", *args], capture_output=True, text=True, timeout=120,
                          cwd=ROOT, stdin=subprocess.DEVNULL)


def statuses(r: subprocess.CompletedProcess) -> dict[str, str]:
    assert r.returncode in (0, 1), r.stderr
    return {c["name"]: c["status"] for c in json.loads(r.stdout)["checks"]}


@pytest.mark.sitl
@pytest.mark.slow
def test_preflight_on_stock_ardupilot_rover_then_fix_the_gcs_failsafe(ardupilot):
    sitl = ardupilot(speedup=SPEEDUP)
    url = sitl.url(0)
    first = statuses(preflight(url))           # the first client on SERIAL0 starts the boot
    assert first["GPS_GLOBAL_ORIGIN"] == "fail" and first["EKF_STATUS_REPORT"] == "fail"
    assert first["HEARTBEAT type"] == "ok" and first["FRAME_CLASS, SERVOn_FUNCTION"] == "ok"

    deadline = time.monotonic() + READY_WALL
    while True:
        r = preflight(url)
        s = statuses(r)
        if all(s[n] == "ok" for n in ESTIMATE):
            break
        assert time.monotonic() < deadline, f"not ready after {READY_WALL:g} s: {s}"
        time.sleep(1.0)
    assert r.returncode == 1
    assert {n for n, v in s.items() if v != "ok"} == {"FS_GCS_ENABLE", "signing"}, s
    checks = {c["name"]: c for c in json.loads(r.stdout)["checks"]}
    assert checks["FRAME_CLASS, SERVOn_FUNCTION"]["value"].startswith("skid-steer")
    assert checks["ATC_STR_RAT_MAX"]["value"] == "120 deg/s"

    fixed = preflight(url, "--fix", "--yes")
    out = json.loads(fixed.stdout)
    assert out["fixes"] == [{"name": "FS_GCS_ENABLE", "from": 0, "to": 1, "read_back": 1,
                             "ok": True}]
    assert {c["name"]: c["status"] for c in out["checks"]}["FS_GCS_ENABLE"] == "ok"
    with GroundStation(sitl) as gs:             # another link reads the vehicle's own value
        asked = time.monotonic()
        gs.mav.param_request_read_send(1, 1, b"FS_GCS_ENABLE", -1)
        value = gs.wait_for("PARAM_VALUE", lambda m: m.param_id == "FS_GCS_ENABLE",
                            timeout=10.0, after=asked)
    assert value.param_value == 1.0
