"""The ground station in the loop on the real autopilot: ArduPilot Rover SITL (``rover-skid``).

A ground station (``gcs_harness.GroundStation``, system 255) on SERIAL0 uploads a mission with
the mission protocol; ``companion mission pull`` on SERIAL1 reads it back into a .plan, compared
item by item; ``companion run --mission vehicle`` flies it, and the ground station hears the
companion's STATUSTEXT and NAMED_VALUE_FLOAT through ArduPilot's routing and pauses / resumes it
with MAV_CMD_DO_PAUSE_CONTINUE. Skipped without ARDUPILOT_SITL (tests/ardupilot_harness.py).
"""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
import time

import pytest

from ardupilot_harness import ROOT, CompanionProcess
from companion.mav import mission_transfer as mt
from companion.mission import geo
from gcs_harness import COMPANION, GroundStation

SPEEDUP = 5
BOOT_WALL = 120.0 / SPEEDUP + 30.0
LEG = [(15.0, 0.0), (15.0, 12.0), (0.0, 12.0)]      # north, east of home (m)


def _items(home: tuple[float, float]) -> list:
    out = [mt.item(0, 16, 0, (0.0, 0.0, 0.0, 0.0), int(round(home[0] * 1e7)),
                   int(round(home[1] * 1e7)), 0.0)]
    out.append(mt.item(1, 178, 2, (1.0, 1.5, -1.0, 0.0), 0, 0, 0.0))    # DO_CHANGE_SPEED 1.5
    for north, east in LEG:
        lat, lon = geo.latlon_from_ne(north, east, home)
        out.append(mt.waypoint(len(out), lat, lon, 0.0))
    return out


@pytest.mark.sitl
@pytest.mark.slow
def test_uploaded_pulled_identical_flown_within_1m_and_paused_from_the_gcs(ardupilot, tmp_path):
    sitl = ardupilot(speedup=SPEEDUP)
    with GroundStation(sitl.url(0)) as gcs:
        hb = gcs.wait_for(lambda: gcs.of("HEARTBEAT", (1, 1)), 30.0, "the vehicle's heartbeat")
        assert hb
        home_msg = gcs.wait_for(lambda: [m for m in gcs.of("GPS_RAW_INT", (1, 1))
                                         if m.fix_type >= 3], 60.0, "a 3-D GPS fix")
        home = (home_msg[-1].lat / 1e7, home_msg[-1].lon / 1e7)
        items = _items(home)
        gcs.upload(1, items)
        sitl.wait_log("SERIAL1 on TCP port", 15.0)
        out = tmp_path / "pulled.plan"
        t0 = time.monotonic()
        r = subprocess.run([sys.executable, "-m", "companion", "mission", "pull", "--connect",
                            sitl.url(1), "--out", str(out)], capture_output=True, text=True,
                           timeout=60, cwd=ROOT)
        pull_wall = time.monotonic() - t0
        assert r.returncode == 0, r.stderr
        pulled = mt.plan_items(json.loads(out.read_text()), home_item=True)
        # item 0 is the vehicle's own home (ArduPilot ignores an uploaded item 0): the rest
        # must be what the ground station uploaded, but for one field ArduPilot itself rewrites:
        # a DO command is stored without a frame and read back in MAV_FRAME_GLOBAL (0), not
        # the MAV_FRAME_MISSION (2) it was uploaded in
        diff = mt.same_items(pulled[1:], items[1:])
        assert diff == ["item 0: frame 0 != 2"], diff
        logs = tmp_path / "logs"
        with CompanionProcess(sitl.url(1), "--mission", "vehicle", "--arm", "--no-zenoh",
                              "--json", "--log-dir", str(logs), "--w-c", "1.2",
                              "--max-speed", "2", "--max-yaw-rate", "1.5") as comp:
            me = (1, COMPANION)
            gcs.wait_for(lambda: any("tracking" in t for t in gcs.texts(me)), BOOT_WALL,
                         "tracking")
            time.sleep(1.0)
            assert gcs.command(me, 193, 0) == 0
            gcs.wait_for(lambda: any("paused" in t for t in gcs.texts(me)), 5.0, "paused")
            time.sleep(1.0)
            assert gcs.command(me, 193, 1) == 0
            gcs.wait_for(lambda: any("resumed" in t for t in gcs.texts(me)), 5.0, "resumed")
            code = comp.wait(180.0)
            time.sleep(0.5)
    assert code == 0, comp.stderr
    res = comp.result()
    texts = gcs.texts(me)
    for want in ("PZC: tracking", "PZC: paused", "PZC: resumed", "PZC: mission done",
                 "PZC: stopped"):
        assert any(t.startswith(want) for t in texts), (want, texts)
    names = {m.name for m in gcs.of("NAMED_VALUE_FLOAT", me)}
    assert names == {"pzc_err", "pzc_state", "pzc_prog", "pzc_mt"}
    rows = list(csv.DictReader(open(res["csv"], newline="")))
    track = [(float(w["x"]), float(w["y"])) for w in rows if w["x"]]
    origin = res["ekf_origin"]
    misses = []
    for north, east in LEG:
        lat, lon = geo.latlon_from_ne(north, east, home)
        n, e = geo.ne_from_latlon(lat, lon, (origin["lat"], origin["lon"]))
        misses.append(min(math.hypot(x - n, y - e) for x, y in track))
    print(f"\nArduPilot SITL: mission of {len(items)} items pulled in {pull_wall:.2f} s wall, "
          f"identical past home; waypoints passed within {[round(m, 3) for m in misses]} m; "
          f"steady RMS {res['steady_rms']:.3f} m; GCS heard {len(texts)} texts: {texts}")
    assert max(misses) < 1.0, misses
