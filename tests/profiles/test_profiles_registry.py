"""A third autopilot is one module and one line of registration (docs/design/profiles.md).

``tests/profiles/madeup_autopilot.py`` is a made-up autopilot, "Acme", with its own setpoint encoding and
reading, failsafe report and preflight checks: here it is registered (the one line a real one
adds to ``companion/profiles/__init__.py``) and flown through the companion's link to the plant
over loopback UDP (encode -> the plant's reading -> the rover moves), its failsafe texts read by
the live health watch, its preflight rows from the frontend. No other file names it. The
steering kinds and manoeuvres every registered profile names exist.
"""

from __future__ import annotations

import threading
import time

import madeup_autopilot as acme
import pytest

import companion.profiles as profiles
from companion.core.signals import Command
from companion.ident.excite import manoeuvres
from companion.live import health
from companion.live.link import Link, LinkConfig
from companion.preflight.checks import Observed, run_checks
from companion.profiles.setpoint import TurnRateSpeed
from sitl_plant.config import PlantConfig
from sitl_plant.link import Link as PlantLink
from sitl_plant.server import PlantServer
from sitl_plant.testing import free_udp_port
from sitl_plant.vehicle import VehicleConfig


@pytest.fixture
def registered(monkeypatch):
    """Acme in the registry, as its one line in AUTOPILOTS would put it."""
    monkeypatch.setitem(profiles.AUTOPILOTS, acme.PROFILE.name, acme.PROFILE)
    return acme.PROFILE


def test_a_made_up_autopilot_flies_from_the_link_through_the_plant(registered):
    port = free_udp_port()
    config = PlantConfig(connect=f"udpout:127.0.0.1:{port}", loop_rate=50.0,
                         vehicle=VehicleConfig(autopilot=registered))
    server = PlantServer(config, PlantLink(config.connect, config.sysid, config.compid))
    plant = threading.Thread(target=server.run, daemon=True)
    link = Link(LinkConfig(url=f"udpin:127.0.0.1:{port}", heartbeat_timeout=5.0))
    plant.start()
    try:
        vehicle = link.wait_vehicle()                 # its heartbeat's id finds its profile
        assert vehicle.profile is registered and vehicle.autopilot == "acme"
        link.request_mode(registered.track_mode)
        link.request_arm()
        deadline = time.monotonic() + 5.0
        while not (server.vehicle.armed and server.vehicle.takes_setpoints):
            assert time.monotonic() < deadline, "Acme never took its track mode and armed"
            time.sleep(0.02)
        # u_p of 1 m/s and 0.2 rad/s: Acme's encoding sends all three, its reading drives the
        # turn rate at the vector's speed
        cmd = Command(speed=0.0, yaw_rate=0.2, ux=0.6, uy=0.8)
        assert registered.setpoint.encode(cmd) == (0.6, 0.8, 0.2)
        deadline = time.monotonic() + 10.0
        while server.vehicle.state.v < 0.5 or server.vehicle.state.omega < 0.1:
            v = server.vehicle
            assert time.monotonic() < deadline, (v.setpoints_ignored, v.setpoints_used, v.t,
                                                 v.mode.name, v.armed, v.target, v.state)
            link.send_command(cmd, 0)
            time.sleep(0.02)                           # a 50 Hz stream, as a loop sends it
        target = server.vehicle.target                 # float32 on the wire
        assert isinstance(target, TurnRateSpeed)
        assert (target.speed, target.yaw_rate) == pytest.approx((1.0, 0.2), rel=1e-6)
    finally:
        server.stopping = True
        link.close()
        plant.join(timeout=5.0)


def test_a_made_up_autopilot_reports_its_failsafes_and_checks_itself(registered):
    watch = health.FailsafeWatch(registered.failsafe)
    assert watch.text("Acme lost you", 1.0) == "gcs"
    rows = {r.name: r for r in run_checks(Observed(
        autopilot="acme", mav_type=10, modes=frozenset({"FOLLOW", "HOLD"}),
        params={"ACME_STEER": 1, "ACME_FS_TIME": 3.0}))}
    assert rows["ACME_STEER"].status == "warn" and rows["ACME_STEER"].value == "Ackermann"
    assert rows["ACME_FS_TIME"].status == "warn" and rows["ACME_FS_TIME"].fix == {"ACME_FS_TIME": 1.0}
    assert rows["FOLLOW"].status == "ok"
    assert profiles.steering_from_params(registered, {"ACME_STEER": 0}) is profiles.STEERING["skid"]


def test_every_profile_names_a_manoeuvre_identification_has():
    known = manoeuvres()
    assert all(p.ident.manoeuvre is None or p.ident.manoeuvre in known
               for p in profiles.AUTOPILOTS.values())
    assert all(s.manoeuvre in known for s in profiles.STEERING.values())
