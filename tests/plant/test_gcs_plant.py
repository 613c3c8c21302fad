"""The ground station in the loop, against a real ``sitl-plant`` with a second link (``--gcs``)
on which a test ground station listens and talks as QGroundControl would. Real processes,
real UDP: a mission uploaded by the GCS is pulled by ``companion mission pull`` item for item
and flown by ``companion run --mission vehicle``; the GCS hears the companion's STATUSTEXT and
NAMED_VALUE_FLOAT and pauses / resumes it with MAV_CMD_DO_PAUSE_CONTINUE; ``--start-on-guided``
waits for the GCS to engage."""

from __future__ import annotations

import contextlib
import csv
import json
import math
import signal
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

from companion.mav import mission_transfer as mt
from companion.mission import geo
from sitl_plant.earth import CMAC
from sitl_plant.testing import PlantProcess, free_udp_port
from testbed.fake_vehicle import is_mode_command
from testbed.mission_gcs import COMPANION, GroundStation
from testbed.missions import ellipse_mission
from testbed.process import ROOT, Companion
from testbed.udp_proxy import Proxy

ORIGIN = CMAC[:2]
LEG = [(0.0, 0.0), (12.0, 0.0), (12.0, 10.0), (0.0, 10.0)]     # north, east (m): home first


def square_items() -> list:
    """Home, then three waypoints and a DO_CHANGE_SPEED, as a GCS would upload them."""
    out = []
    for north, east in LEG:
        lat, lon = geo.latlon_from_ne(north, east, ORIGIN)
        out.append(mt.waypoint(len(out), lat, lon, 0.0 if not out else 2.0))
    out[0].frame = 0                          # home: MAV_FRAME_GLOBAL, as ArduPilot keeps it
    out.insert(1, mt.item(1, 178, 2, (1.0, 2.0, -1.0, 0.0), 0, 0, 0.0))   # DO_CHANGE_SPEED 2 m/s
    for i, it in enumerate(out):
        it.seq = i
    return out


def pull(port: int, *args: str, timeout: float = 30.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "companion", "mission", "pull", "--connect",
                           f"udpin:127.0.0.1:{port}", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


def test_a_mission_uploaded_by_a_gcs_is_pulled_identical_and_flown(tmp_path):
    gcs_port = free_udp_port()
    items = square_items()
    with PlantProcess("--speedup", "2", "--gcs", f"udpout:127.0.0.1:{gcs_port}") as plant, \
            GroundStation(f"udpin:127.0.0.1:{gcs_port}") as gcs:
        gcs.wait_for(lambda: gcs.of("HEARTBEAT", (1, 1)), 10.0, "the plant's heartbeat")
        gcs.upload(1, items)
        out = tmp_path / "pulled.plan"
        r = pull(plant.port, "--out", str(out))
        assert r.returncode == 0, r.stderr
        plan = json.loads(out.read_text())
        assert mt.same_items(mt.plan_items(plan, home_item=True), items) == []
        assert "5 items written" in r.stderr
        # and flown: every waypoint passed within 1 m
        comp = Companion(plant.port, "--arm", "--no-zenoh", "--json", "--mission", "vehicle",
                         "--log-dir", str(tmp_path))
        with comp:
            code = comp.wait(90.0)
    assert code == 0, comp.stderr
    assert "pulled the vehicle's mission: 5 items" in comp.stderr
    rows = list(csv.DictReader(next(tmp_path.glob("*.csv")).open()))
    track = [(float(r["x"]), float(r["y"])) for r in rows if r["x"]]
    for north, east in LEG[1:]:
        miss = min(math.hypot(x - north, y - east) for x, y in track)
        assert miss < 1.0, (north, east, miss)
        print(f"\nwaypoint ({north:g}, {east:g}) passed within {miss:.3f} m")


def test_a_mission_uploaded_at_boot_waits_for_the_vehicles_home_then_flies(tmp_path):
    """Uploaded before the vehicle's first fix with the home a GCS knew then (0, 0), and run
    at once (a systemd unit at power-on): the run waits for the vehicle's home (the plant's
    origin 6 vehicle s after boot), places the mission there and flies it."""
    gcs_port = free_udp_port()
    items = square_items()
    items[0].x, items[0].y = 0, 0
    with PlantProcess("--speedup", "2", "--origin-delay", "6", "--gcs",
                      f"udpout:127.0.0.1:{gcs_port}") as plant, \
            GroundStation(f"udpin:127.0.0.1:{gcs_port}") as gcs:
        gcs.wait_for(lambda: gcs.of("HEARTBEAT", (1, 1)), 10.0, "the plant's heartbeat")
        gcs.upload(1, items)
        comp = Companion(plant.port, "--arm", "--no-zenoh", "--json", "--mission", "vehicle",
                         "--log-dir", str(tmp_path))
        with comp:
            code = comp.wait(90.0)
    assert code == 0, comp.stderr
    assert "has no home yet (0, 0" in comp.stderr and "home is set after" in comp.stderr
    plan = json.loads(next(tmp_path.glob("vehicle-mission-*.plan")).read_text())
    home = plan["mission"]["plannedHomePosition"]
    assert geo.ne_from_latlon(home[0], home[1], ORIGIN) == pytest.approx((0.0, 0.0), abs=0.01)
    rows = list(csv.DictReader(next(tmp_path.glob("*.csv")).open()))
    track = [(float(r["x"]), float(r["y"])) for r in rows if r["x"]]
    for north, east in LEG[1:]:
        assert min(math.hypot(x - north, y - east) for x, y in track) < 1.0, (north, east)


def test_a_vehicle_that_never_gets_a_home_is_refused_after_the_origin_timeout(tmp_path):
    gcs_port = free_udp_port()
    items = square_items()
    items[0].x, items[0].y = 0, 0
    with PlantProcess("--origin-delay", "100000", "--gcs",
                      f"udpout:127.0.0.1:{gcs_port}") as plant, \
            GroundStation(f"udpin:127.0.0.1:{gcs_port}") as gcs:
        gcs.wait_for(lambda: gcs.of("HEARTBEAT", (1, 1)), 10.0, "the plant's heartbeat")
        gcs.upload(1, items)
        comp = Companion(plant.port, "--arm", "--no-zenoh", "--json", "--mission", "vehicle",
                         "--origin-timeout", "3", "--log-dir", str(tmp_path))
        with comp:
            code = comp.wait(60.0)
    assert code == 2, comp.stderr
    last = comp.stderr.strip().splitlines()[-1]
    assert "still had no home after 3 s" in last and "Traceback" not in comp.stderr


def test_a_partial_transfer_writes_nothing_and_says_so(tmp_path):
    gcs_port = free_udp_port()
    with PlantProcess("--speedup", "2", "--gcs", f"udpout:127.0.0.1:{gcs_port}",
                      "--mission-drop-item", "2") as plant, \
            GroundStation(f"udpin:127.0.0.1:{gcs_port}") as gcs:
        gcs.wait_for(lambda: gcs.of("HEARTBEAT", (1, 1)), 10.0, "the plant's heartbeat")
        gcs.upload(1, square_items())
        out = tmp_path / "pulled.plan"
        r = pull(plant.port, "--out", str(out), "--timeout", "0.3", "--retries", "2")
    assert r.returncode == 3, r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert "partial mission transfer refused: item 2 of 5 never came" in last, r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists() and not list(tmp_path.iterdir())


def test_no_vehicle_is_a_user_error(tmp_path):
    r = pull(free_udp_port(), "--heartbeat-timeout", "1", "--out", str(tmp_path / "x.plan"))
    assert r.returncode == 2 and "no heartbeat" in r.stderr and "Traceback" not in r.stderr


def test_the_gcs_hears_the_companion_and_pauses_and_resumes_it(tmp_path):
    gcs_port = free_udp_port()
    mission = ellipse_mission(tmp_path / "m.toml", 14.0)
    with PlantProcess("--speedup", "2", "--gcs", f"udpout:127.0.0.1:{gcs_port}") as plant, \
            GroundStation(f"udpin:127.0.0.1:{gcs_port}") as gcs, \
            Companion(plant.port, "--arm", "--no-zenoh", "--json", "--no-log", "--mission",
                      str(mission)) as comp:
        me = (1, COMPANION)
        gcs.wait_for(lambda: any("tracking" in t for t in gcs.texts(me)), 30.0, "tracking")
        time.sleep(1.0)
        assert gcs.command(me, 193, 0) == 0                 # pause: accepted
        gcs.wait_for(lambda: any("paused" in t for t in gcs.texts(me)), 5.0, "paused")
        t_pause = time.monotonic()
        time.sleep(2.0)
        during = [m for m in gcs.of("NAMED_VALUE_FLOAT", me, t_pause + 0.5)]
        assert gcs.command(me, 193, 0) == 1                 # pause again: temporarily rejected
        assert gcs.command(me, 193, 1) == 0                 # continue: accepted
        gcs.wait_for(lambda: any("resumed" in t for t in gcs.texts(me)), 5.0, "resumed")
        code = comp.wait(60.0)
        time.sleep(0.5)
    assert code == 0, comp.stderr
    texts = gcs.texts(me)
    assert all(len(t) <= 50 for t in texts)
    for want in ("PZC: connected", "PZC: tracking", "PZC: paused", "PZC: refused: cannot "
                 "pause while paused", "PZC: resumed", "PZC: mission done", "PZC: stopped"):
        assert any(t.startswith(want) for t in texts), (want, texts)
    names = {m.name for m in gcs.of("NAMED_VALUE_FLOAT", me)}
    assert names == {"pzc_err", "pzc_state", "pzc_prog", "pzc_mt"}
    paused_mt = {round(m.value, 6) for m in during if m.name == "pzc_mt"}
    paused_state = {m.value for m in during if m.name == "pzc_state"}
    assert len(paused_mt) == 1 and paused_state == {4.0}, (paused_mt, paused_state)
    err = [m.value for m in gcs.of("NAMED_VALUE_FLOAT", me) if m.name == "pzc_err"]
    assert err and all(math.isfinite(e) for e in err) and max(err) > 0.0
    assert max(err[-8:]) < 0.5, err[-8:]        # settled on the path by the end
    hb = gcs.of("HEARTBEAT", me)
    assert hb and hb[0].type == 18                       # MAV_TYPE_ONBOARD_CONTROLLER
    rate = len([m for m in gcs.of("NAMED_VALUE_FLOAT", me) if m.name == "pzc_state"])
    print(f"\nGCS heard {len(texts)} STATUSTEXT and {rate} pzc_state values; texts: {texts}")


def test_a_failsafe_reaches_the_gcs(tmp_path):
    gcs_port = free_udp_port()
    mission = ellipse_mission(tmp_path / "m.toml", 600.0)
    with PlantProcess("--speedup", "2", "--gcs", f"udpout:127.0.0.1:{gcs_port}") as plant, \
            GroundStation(f"udpin:127.0.0.1:{gcs_port}") as gcs, \
            Companion(plant.port, "--arm", "--no-zenoh", "--json", "--no-log", "--mission",
                      str(mission), "--lost-timeout", "2") as comp:
        me = (1, COMPANION)
        gcs.wait_for(lambda: any("tracking" in t for t in gcs.texts(me)), 30.0, "tracking")
        # the GCS turns the pose stream off on the vehicle: the companion's telemetry goes stale
        assert gcs.command((1, 1), 511, 32, -1) == 0
        code = comp.wait(30.0)
        time.sleep(0.5)
    assert code == 3, comp.stderr
    texts = gcs.texts(me)
    fs = [t for t in texts if t.startswith("PZC: FAILSAFE")]
    assert fs and fs[0].startswith("PZC: FAILSAFE: telemetry stale"), texts
    assert any(t.startswith("PZC: stopped: failsafe: telemetry lost") for t in texts), texts
    sev = {m.text: m.severity for m in gcs.of("STATUSTEXT", me)}
    assert sev[fs[0]] == 2                               # MAV_SEVERITY_CRITICAL


def test_start_on_guided_engages_nothing_and_tracks_once_the_gcs_does(tmp_path):
    gcs_port = free_udp_port()
    mission = ellipse_mission(tmp_path / "m.toml", 6.0)
    with Proxy() as proxy, \
            PlantProcess("--speedup", "2", "--gcs", f"udpout:127.0.0.1:{gcs_port}",
                         port=proxy.plant_port), \
            GroundStation(f"udpin:127.0.0.1:{gcs_port}") as gcs, \
            Companion(proxy.companion_port, "--start-on-guided", "--no-zenoh", "--json",
                      "--no-log", "--mission", str(mission)) as comp:
        proxy.wait_for(lambda: len(proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")) > 80,
                       30.0)                             # 2 s of zero setpoints, waiting
        assert comp.proc.poll() is None
        assert not any(is_mode_command(s.msg, 15) for s in proxy.companion_sent("COMMAND_LONG"))
        assert gcs.command((1, 1), 400, 1) == 0          # the GCS arms ...
        assert gcs.command((1, 1), 176, 1, 15) == 0      # ... and selects GUIDED
        code = comp.wait(40.0)
    assert code == 0, comp.stderr
    sent = [s.msg.command for s in proxy.companion_sent("COMMAND_LONG")]
    assert 400 not in sent and not any(is_mode_command(s.msg, 15)
                                       for s in proxy.companion_sent("COMMAND_LONG")), sent
    assert "waiting for the pilot or a ground station to select GUIDED" in comp.stderr
    assert json.loads(comp.stdout.strip().splitlines()[-1])["reason"] == "mission_done"


def handover_items(twice: bool) -> list:
    """Home; waypoint; [enable; two waypoints; disable]; waypoint (x2 with ``twice``)."""
    def wp(north: float, east: float):
        lat, lon = geo.latlon_from_ne(north, east, ORIGIN)
        return mt.waypoint(0, lat, lon, 0.0)

    def guided(on: bool):
        return mt.item(0, 92, 2, (1.0 if on else 0.0, 0.0, 0.0, 0.0), 0, 0, 0.0)

    out = [mt.item(0, 16, 0, (0.0, 0.0, 0.0, 0.0), int(round(ORIGIN[0] * 1e7)),
                   int(round(ORIGIN[1] * 1e7)), 0.0),
           wp(8.0, 0.0), guided(True), wp(14.0, 4.0), wp(10.0, 10.0), guided(False),
           wp(4.0, 12.0)]
    if twice:
        out += [guided(True), wp(0.0, 6.0), wp(-2.0, 0.0), guided(False), wp(4.0, -4.0)]
    for i, it in enumerate(out):
        it.seq = i
    return out


@contextlib.contextmanager
def plant_with_mission(items: list) -> Iterator[tuple[PlantProcess, GroundStation]]:
    """The plant at 2 x with a ground station on its second link, which has uploaded
    ``items`` (the vehicle's mission) once the plant is heard."""
    gcs_port = free_udp_port()
    with PlantProcess("--speedup", "2", "--gcs", f"udpout:127.0.0.1:{gcs_port}") as plant, \
            GroundStation(f"udpin:127.0.0.1:{gcs_port}") as gcs:
        gcs.wait_for(lambda: gcs.of("HEARTBEAT", (1, 1)), 10.0, "the plant's heartbeat")
        gcs.upload(1, items)
        yield plant, gcs


def gcs_arms_and_starts_auto(gcs: GroundStation) -> None:
    """Once the companion is heard: the GCS arms the plant and selects AUTO."""
    gcs.wait_for(lambda: gcs.of("HEARTBEAT", (1, COMPANION)), 20.0, "the companion")
    time.sleep(1.0)
    assert gcs.command((1, 1), 400, 1) == 0
    assert gcs.command((1, 1), 176, 1, 10) == 0          # AUTO, by the GCS


@pytest.mark.slow   # long (about 25 s of real-time flight): its file starts first under workers
def test_handover_inside_auto_twice(tmp_path):
    """AUTO drives to the first waypoint, the companion tracks each enable..disable segment
    from the rover's pose, hands back, AUTO goes on and reaches the last waypoint."""
    items = handover_items(twice=True)
    with plant_with_mission(items) as (plant, gcs):
        with Companion(plant.port, "--handover", "--mission", "vehicle", "--no-zenoh", "--json", "--log-dir",
                       str(tmp_path)) as comp:
            gcs_arms_and_starts_auto(gcs)
            code = comp.wait(120.0)
        time.sleep(0.3)
        reached = [m.seq for m in gcs.of("MISSION_ITEM_REACHED", (1, 1))]
    assert code == 0, comp.stderr
    r = comp.result()
    assert r["reason"].startswith("mission_done: AUTO reached the last mission item"), r
    segs = r["handovers"]
    assert [s["items"] for s in segs] == [[2, 5], [7, 10]], segs
    assert all(s["ended"].startswith("handed back") for s in segs)
    for s in segs:
        assert s["steady_rms"] < 0.2, segs
    assert reached[0] == 1 and reached[-1] == len(items) - 1, reached
    texts = gcs.texts((1, COMPANION))
    assert sum(t.startswith("PZC: tracking: hand-over") for t in texts) == 2, texts
    assert sum(t.startswith("PZC: hand-back") for t in texts) == 2, texts
    print(f"\nhand-overs on the plant: {segs}")


@pytest.mark.parametrize("when", ["after the hand-back", "in the segment"])
def test_a_stop_leaves_auto_its_own_mission_and_holds_a_segment(tmp_path, when):
    """SIGTERM with --handover: while AUTO drives its own items the autopilot's mission is not
    the companion's to stop (AUTO goes on to its last item); while the companion tracks a
    segment it stops the rover (HOLD), as any run does."""
    items = handover_items(twice=False)
    with plant_with_mission(items) as (plant, gcs):
        with Companion(plant.port, "--handover", "--mission", "vehicle", "--no-zenoh", "--json",
                       "--no-log") as comp:
            gcs_arms_and_starts_auto(gcs)
            if when == "in the segment":
                comp.wait_for_stderr("hand-over: tracking", 60.0)
                time.sleep(1.0)
            else:
                comp.wait_for_stderr("hand-over: handed back", 60.0)
            stopped = time.monotonic()
            comp.proc.send_signal(signal.SIGTERM)
            code = comp.wait(20.0)
        modes = lambda: [m.custom_mode for m in gcs.of("HEARTBEAT", (1, 1), stopped)]  # noqa: E731
        if when == "in the segment":
            gcs.wait_for(lambda: 4 in modes(), 10.0, "HOLD after the stop")
        else:
            last = len(items) - 1
            gcs.wait_for(lambda: any(m.seq == last for m in gcs.of("MISSION_ITEM_REACHED",
                                                                   (1, 1), stopped)),
                         60.0, "AUTO reaching its last item after the stop")
            assert set(modes()) == {10}, modes()                  # AUTO all along
    assert code == 0, comp.stderr
    r = comp.result()
    assert r["reason"] == "SIGTERM", r
    if when == "in the segment":
        assert r["hold_confirmed"] is True, r
        assert "left to it" not in comp.stderr
    else:
        assert "AUTO drives its own mission items: left to it, in AUTO" in comp.stderr
        assert not r["hold_confirmed"], r
