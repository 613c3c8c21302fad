"""The ground station in the loop on the real autopilot: ArduPilot Rover SITL (``rover-skid``).

A ground station (``testbed.mission_gcs.GroundStation``, system 255) on SERIAL0 uploads a mission with
the mission protocol; ``companion mission pull`` on SERIAL1 reads it back into a .plan, compared
item by item; ``companion run --mission vehicle`` flies it, and the ground station hears the
companion's STATUSTEXT and NAMED_VALUE_FLOAT through ArduPilot's routing and pauses / resumes it
with MAV_CMD_DO_PAUSE_CONTINUE. Skipped without ARDUPILOT_SITL (testbed/ardupilot.py).
"""

from __future__ import annotations

import csv
import json
import math
import signal
import time

import pytest

from companion.mav import mission_transfer as mt
from companion.mission import geo
from sitl_plant.earth import CMAC
from testbed.ardupilot import CompanionProcess
from testbed.marks import CANDIDATE
from testbed.mission_gcs import COMPANION, GroundStation, waypoint_mission
from testbed.process import companion_cli

SPEEDUP = 5
TRACK_SPEEDUP = 2
BOOT_WALL = 120.0 / TRACK_SPEEDUP + 30.0
LEG = [(15.0, 0.0), (15.0, 12.0), (0.0, 12.0)]      # north, east of home (m)


def _waypoint_misses(res: dict, home: tuple[float, float]) -> list[float]:
    """How close a run (its JSON: the CSV, the EKF origin) came to each waypoint of LEG, m."""
    rows = list(csv.DictReader(open(res["csv"], newline="")))
    track = [(float(w["x"]), float(w["y"])) for w in rows if w["x"]]
    origin = (res["ekf_origin"]["lat"], res["ekf_origin"]["lon"])
    misses = []
    for north, east in LEG:
        lat, lon = geo.latlon_from_ne(north, east, home)
        n, e = geo.ne_from_latlon(lat, lon, origin)
        misses.append(min(math.hypot(x - n, y - e) for x, y in track))
    return misses


def _items(home: tuple[float, float]) -> list:
    return waypoint_mission(home, LEG, 1.0)


@pytest.mark.sitl
@pytest.mark.slow
def test_uploaded_pulled_identical_flown_within_1m_and_paused_from_the_gcs(ardupilot, tmp_path):
    # x2, not x5: the waypoint test has 1 m for the tracking and the 0.83 m a rounded corner
    # takes; at x5 a loaded machine (three SITLs on two cores) made it 1.17-1.33 m
    sitl = ardupilot(speedup=TRACK_SPEEDUP)
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
        # The guard is the command's own give-up, not a speed bound: each request is sent
        # again after 1.5 s, five times (mav.mission_transfer), and SITL's SERIAL1 under a
        # doubled load (make test beside make sitl-test, 2026-12-03) passed a 60 s guard once
        r = companion_cli("mission", "pull", "--connect", sitl.url(1), "--out", str(out),
                          timeout=180)
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
    misses = _waypoint_misses(res, home)
    print(f"\nArduPilot SITL: mission of {len(items)} items pulled in {pull_wall:.2f} s wall, "
          f"identical past home; waypoints passed within {[round(m, 3) for m in misses]} m; "
          f"steady RMS {res['steady_rms']:.3f} m; GCS heard {len(texts)} texts: {texts}")
    assert max(misses) < 1.0, misses


@CANDIDATE
@pytest.mark.sitl
@pytest.mark.slow
def test_a_mission_uploaded_while_booting_flies_once_the_vehicle_has_a_home(ardupilot, tmp_path):
    """Issue 45: a mission uploaded while the autopilot boots (no GPS fix, its home 0, 0) and
    `run --mission vehicle` started within 5 s of the boot (a systemd unit at power-on): the
    run waits for the vehicle's home, then flies the mission from there."""
    sitl = ardupilot(speedup=1)            # the first fix about 10 s after boot, as on a board
    with GroundStation(sitl.url(0)) as gcs:
        gcs.wait_for(lambda: gcs.of("HEARTBEAT", (1, 1)), 30.0, "the vehicle's heartbeat")
        booted = time.monotonic()
        home = CMAC[:2]                    # where SITL will be: the GCS drew around it
        items = _items(home)
        items[0].x, items[0].y = 0, 0      # home unknown to the GCS yet
        while True:     # its mission storage refuses uploads for the first moments of the boot
            try:
                gcs.upload(1, items)
                break
            except mt.TransferError:
                assert time.monotonic() - booted < 10.0, "uploads refused 10 s after boot"
                time.sleep(0.5)
        uploaded = time.monotonic() - booted
        sitl.wait_log("SERIAL1 on TCP port", 15.0)
        logs = tmp_path / "logs"
        with CompanionProcess(sitl.url(1), "--mission", "vehicle", "--arm", "--no-zenoh",
                              "--json", "--log-dir", str(logs), "--w-c", "1.2",
                              "--max-speed", "2", "--max-yaw-rate", "1.5") as comp:
            started = time.monotonic() - booted
            code = comp.wait(300.0)
    res = comp.result()
    print(f"\nuploaded {uploaded:.1f} s and started {started:.1f} s after the boot; "
          + "; ".join(line for line in comp.stderr.splitlines() if "home" in line))
    assert started <= 5.0
    assert code == 0 and res["reason"] == "mission_done", comp.stderr
    assert "has no home yet (0, 0" in comp.stderr and "home is set after" in comp.stderr
    misses = _waypoint_misses(res, home)
    assert max(misses) < 1.0, misses


def _handover_items(home: tuple[float, float]) -> list:
    def wp(north: float, east: float):
        lat, lon = geo.latlon_from_ne(north, east, home)
        return mt.waypoint(0, lat, lon, 0.0)

    def guided(on: bool):
        return mt.item(0, 92, 2, (1.0 if on else 0.0, 0.0, 0.0, 0.0), 0, 0, 0.0)

    out = [mt.item(0, 16, 0, (0.0, 0.0, 0.0, 0.0), int(round(home[0] * 1e7)),
                   int(round(home[1] * 1e7)), 0.0),
           mt.item(0, 178, 2, (1.0, 1.5, -1.0, 0.0), 0, 0, 0.0),
           wp(12.0, 0.0), guided(True), wp(20.0, 6.0), wp(14.0, 14.0), guided(False),
           wp(4.0, 16.0), guided(True), wp(-2.0, 8.0), wp(2.0, 0.0), guided(False),
           wp(10.0, -6.0)]
    for i, it in enumerate(out):
        it.seq = i
    return out


@pytest.mark.sitl
@pytest.mark.slow
def test_handover_inside_auto_twice_on_ardupilot(ardupilot, tmp_path):
    """waypoint, NAV_GUIDED_ENABLE 1, two waypoints, NAV_GUIDED_ENABLE 0, waypoint, and once
    more: ArduPilot's AUTO drives itself to the waypoints outside the segments, the companion
    tracks each segment and hands back, AUTO reaches the last waypoint."""
    sitl = ardupilot(speedup=SPEEDUP)
    with GroundStation(sitl.url(0)) as gcs:
        fix = gcs.wait_for(lambda: [m for m in gcs.of("GPS_RAW_INT", (1, 1))
                                    if m.fix_type >= 3], 60.0, "a 3-D GPS fix")
        home = (fix[-1].lat / 1e7, fix[-1].lon / 1e7)
        items = _handover_items(home)
        gcs.upload(1, items)
        sitl.wait_log("SERIAL1 on TCP port", 15.0)
        with CompanionProcess(sitl.url(1), "--handover", "--mission", "vehicle", "--no-zenoh",
                              "--json",
                              "--log-dir", str(tmp_path / "logs"), "--w-c", "1.2",
                              "--max-speed", "2", "--max-yaw-rate", "1.5") as comp:
            gcs.wait_for(lambda: gcs.of("HEARTBEAT", (1, COMPANION)), 30.0, "the companion")
            deadline = time.monotonic() + BOOT_WALL
            while gcs.command((1, 1), 400, 1) != 0:          # the GCS arms (EKF permitting)
                assert time.monotonic() < deadline, "never armed"
                time.sleep(1.0)
            while gcs.command((1, 1), 176, 1, 10) != 0:      # ... and starts AUTO (once the
                assert time.monotonic() < deadline, gcs.texts((1, 1))   # EKF has a position)
                time.sleep(1.0)
            code = comp.wait(240.0)
        time.sleep(0.5)
        reached = [m.seq for m in gcs.of("MISSION_ITEM_REACHED", (1, 1))]
    assert code == 0, comp.stderr
    r = comp.result()
    segs = r["handovers"]
    print(f"\nArduPilot SITL hand-overs: {segs}; items reached {reached}; reason {r['reason']}")
    assert [s["items"] for s in segs] == [[3, 6], [8, 11]], segs
    assert all(s["ended"].startswith("handed back") for s in segs), segs
    assert r["reason"].startswith("mission_done: AUTO reached the last mission item"), r
    assert 2 in reached and len(items) - 1 in reached, reached


@pytest.mark.sitl
@pytest.mark.slow
def test_a_stop_after_the_hand_back_leaves_auto_its_mission_on_ardupilot(ardupilot, tmp_path):
    """SIGTERM with --handover once the first segment is handed back: the companion sends
    nothing more (no HOLD), and ArduPilot's AUTO drives the waypoint after the segment."""
    sitl = ardupilot(speedup=SPEEDUP)
    with GroundStation(sitl.url(0)) as gcs:
        fix = gcs.wait_for(lambda: [m for m in gcs.of("GPS_RAW_INT", (1, 1))
                                    if m.fix_type >= 3], 60.0, "a 3-D GPS fix")
        items = _handover_items((fix[-1].lat / 1e7, fix[-1].lon / 1e7))
        gcs.upload(1, items)
        sitl.wait_log("SERIAL1 on TCP port", 15.0)
        with CompanionProcess(sitl.url(1), "--handover", "--mission", "vehicle", "--no-zenoh",
                              "--json", "--no-log", "--w-c", "1.2", "--max-speed", "2",
                              "--max-yaw-rate", "1.5") as comp:
            gcs.wait_for(lambda: gcs.of("HEARTBEAT", (1, COMPANION)), 30.0, "the companion")
            deadline = time.monotonic() + BOOT_WALL
            while gcs.command((1, 1), 400, 1) != 0:          # the GCS arms (EKF permitting)
                assert time.monotonic() < deadline, "never armed"
                time.sleep(1.0)
            while gcs.command((1, 1), 176, 1, 10) != 0:      # ... and starts AUTO
                assert time.monotonic() < deadline, gcs.texts((1, 1))
                time.sleep(1.0)
            comp.wait_for_stderr("hand-over: handed back to AUTO at item 6", 180.0)
            stopped = time.monotonic()
            comp.proc.send_signal(signal.SIGTERM)
            code = comp.wait(20.0)
        # AUTO drove to the waypoint after the disable (item 7) by itself and went on to the
        # next enable (8; this build says no "Reached waypoint" for item 7: its current item
        # is what tells)
        gcs.wait_for(lambda: any(m.seq == 8 for m in gcs.of("MISSION_CURRENT", (1, 1),
                                                            stopped)),
                     120.0, "AUTO done with item 7 after the stop")
        modes = [m.custom_mode for m in gcs.of("HEARTBEAT", (1, 1), stopped)]
    assert code == 0, comp.stderr
    r = comp.result()
    assert r["reason"] == "SIGTERM" and not r["hold_confirmed"], r
    assert "AUTO drives its own mission items: left to it, in AUTO" in comp.stderr
    assert modes and set(modes) == {10}, modes                    # AUTO all along
    print(f"\nstopped after the hand-back: AUTO drove item 7 itself, {len(modes)} heartbeats "
          "in AUTO")


@pytest.mark.sitl
@pytest.mark.slow
@pytest.mark.parametrize("identity", ["onboard", "255"])
def test_the_gcs_failsafe_still_fires_while_the_companion_runs(ardupilot, tmp_path, identity):
    """FS_GCS_ENABLE 1: the ground station (system 255) goes silent while the companion tracks.
    With the companion's onboard identity (the vehicle's system id, component 191) ArduPilot's
    GCS failsafe fires and stops the rover; heart-beating as 255 (``--source-system 255``, what
    the companion did before) it keeps the failsafe from ever firing."""
    from testbed.missions import circle_mission
    # FS_GCS_TIMEOUT is vehicle time, heartbeats come once a wall second: at SPEEDUP 5 a 5 s
    # timeout is one wall second and a late heartbeat under load trips it; 20 s is 4 wall s
    sitl = ardupilot(speedup=SPEEDUP, params={"FS_GCS_ENABLE": 1, "FS_GCS_TIMEOUT": 20})
    mission = circle_mission(tmp_path / "circle.toml", duration=600.0)
    extra = ["--source-system", "255"] if identity == "255" else []
    gcs = GroundStation(sitl.url(0)).__enter__()
    gcs.wait_for(lambda: gcs.of("HEARTBEAT", (1, 1)), 30.0, "the vehicle's heartbeat")
    sitl.wait_log("SERIAL2 on TCP port", 15.0)
    # a listener that is no ground station (system 250: not MAV_GCS_SYSID): the vehicle's texts
    watch = GroundStation(sitl.url(2), sysid=250).__enter__()
    with CompanionProcess(sitl.url(1), "--mission", str(mission), "--arm", "--no-zenoh",
                          "--json", "--no-log", "--w-c", "1.2", *extra) as comp:
        me = (255 if identity == "255" else 1, COMPANION)
        gcs.wait_for(lambda: any("tracking" in t for t in gcs.texts(me)), BOOT_WALL, "tracking")
        time.sleep(2.0)
        gcs.__exit__(None, None, None)                   # the ground station is lost
        t_lost = time.monotonic()
        try:
            code = comp.wait(10.0 + 60.0 / SPEEDUP)      # FS_GCS_TIMEOUT 20 vehicle s + margin
        except AssertionError:
            code = None                                  # still tracking: no failsafe
        waited = time.monotonic() - t_lost
    time.sleep(0.5)
    watch.__exit__(None, None, None)
    said = watch.texts((1, 1))
    if identity == "onboard":
        # the autopilot's own failsafe took the vehicle: named as such, never taken back
        assert code == 5, comp.stderr                    # ExitCode.AUTOPILOT_FAILSAFE
        assert "failsafe" in comp.stderr, comp.stderr
        # this build words its GCS failsafe "Radio Failsafe" (with FS_GCS_ENABLE 0 nothing
        # happens at all: seen 2026-12-02)
        assert any("ailsafe" in t for t in said), " | ".join(said[-12:])
        print(f"\nonboard identity: GCS failsafe after {waited:.2f} s wall "
              f"({waited * SPEEDUP:.1f} vehicle s at x{SPEEDUP}); companion exit {code}; "
              f"the vehicle said {[t for t in said if 'ailsafe' in t]}")
    else:
        assert code is None, comp.stderr
        assert not any("ailsafe" in t for t in said), said
        print(f"\n--source-system 255: no GCS failsafe in {waited:.1f} s wall "
              f"({waited * SPEEDUP:.0f} vehicle s) after the ground station was lost")
