"""The loop's ControlChannel (what the Zenoh control queryable will drive): status, start,
pause, resume, load-mission, abort, against a real plant process over UDP."""

from __future__ import annotations

import json
import threading
import time

from companion import mission as missions
from companion.live.events import ControlChannel
from companion.live.link import LinkConfig
from companion.live.runner import RunnerConfig
from companion.live.session import RunSettings, fly
from sitl_plant.testing import PlantProcess, free_udp_port

MISSION_TEXT = 'name = "loaded"\nduration = 20\n[trajectory]\nkind = "ellipse"\nf_r = 0.12\n'


def _status(control: ControlChannel) -> dict:
    ok, text = control.submit("status", timeout=5.0)
    assert ok, text
    return json.loads(text)


def _wait_state(control, state, timeout=20.0):
    """Every status request is answered: by the setup ("setting_up") until the loop runs."""
    deadline = time.monotonic() + timeout
    s: dict = {}
    while time.monotonic() < deadline:
        s = _status(control)
        if s["state"] == state:
            return s
        time.sleep(0.05)
    raise AssertionError(f"never reached {state} within {timeout:g} s: {s}")


def test_control_verbs_drive_the_loop():
    control = ControlChannel()
    out: dict = {}
    with PlantProcess("--speedup", "4", "--d-cen", "0.3", sysid=3) as plant:
        settings = RunSettings(
            link=LinkConfig(url=f"udpin:127.0.0.1:{plant.port}", sysid=3),
            mission=missions.paper_ellipse(0.12, 60.0),
            runner=RunnerConfig(arm=True, autostart=False))
        worker = threading.Thread(target=lambda: out.setdefault("r", fly(settings,
                                                                          control=control)))
        worker.start()
        try:
            _wait_state(control, "ready", timeout=40.0)
            assert control.submit("pause") == (False, "cannot pause while ready")
            assert control.submit("start")[0]
            s = _wait_state(control, "tracking")
            time.sleep(1.0)
            ok, text = control.submit("load-mission", MISSION_TEXT)
            assert not ok and "pause first" in text
            assert control.submit("pause")[0]
            t_paused = _status(control)["mission_time"]
            time.sleep(0.5)
            assert _status(control)["mission_time"] == t_paused     # the clock stands still
            assert control.submit("resume")[0]
            time.sleep(0.5)
            assert _status(control)["mission_time"] > t_paused
            assert control.submit("pause")[0]
            ok, text = control.submit("load-mission", MISSION_TEXT)
            assert ok, text
            s = _status(control)
            assert (s["state"], s["mission"], s["mission_time"]) == ("ready", "loaded", 0.0)
            assert not control.submit("load-mission", "kind = 3")[0]
            assert control.submit("start")[0]
            time.sleep(0.5)
            assert control.submit("jump")[0] is False
            assert control.submit("abort")[0]
            worker.join(15.0)
            assert not worker.is_alive()
        finally:
            if worker.is_alive():     # never leave the loop running: ask it to stop
                control.submit("abort")
                worker.join(10.0)
    r = out["r"]
    assert r.reason == "aborted" and r.exit_code == 0 and r.hold_confirmed
    assert r.sysid == 3 and r.mission == "loaded" and 0 < r.duration_s < 20.0


def _fly_in_thread(settings, control, out):
    def target():
        try:
            out["r"] = fly(settings, control=control)
        except BaseException as exc:   # noqa: BLE001 - what the session raised is the result
            out["raised"] = exc
    worker = threading.Thread(target=target)
    worker.start()
    return worker


def test_the_setup_answers_status_and_abort_before_any_vehicle_is_heard():
    """Nothing answers on the port: the session waits for a heartbeat (30 s by default). A
    status request is answered meanwhile, saying what the setup is doing; other verbs are
    refused naming it; abort ends the setup at once, as Ctrl-C there does (interrupted)."""
    control = ControlChannel()
    out: dict = {}
    port = free_udp_port()
    settings = RunSettings(link=LinkConfig(url=f"udpin:127.0.0.1:{port}"),
                           mission=missions.paper_ellipse(0.04, 60.0))
    worker = _fly_in_thread(settings, control, out)
    try:
        s = _status(control)
        assert (s["state"], s["step"]) == ("setting_up", "waiting for the vehicle's heartbeat")
        assert (s["mission"], s["duration"], s["mode"], s["cycles"]) == ("paper ellipse 0.04 Hz", 60.0, None, 0)
        ok, text = control.submit("start")
        assert not ok and text.startswith("still setting up (waiting for the vehicle's heartbeat)")
        t0 = time.monotonic()
        ok, text = control.submit("abort")
        assert ok and "nothing is asked of the vehicle" in text, text
        worker.join(5.0)
        assert not worker.is_alive() and time.monotonic() - t0 < 5.0
    finally:
        if worker.is_alive():
            control.submit("abort")
            worker.join(35.0)
    assert isinstance(out.get("raised"), KeyboardInterrupt), out


def test_an_abort_during_the_setup_ends_the_run_without_asking_the_vehicle_anything(tmp_path):
    """A vehicle that sends heartbeats and answers no command (a slow link, a busy autopilot):
    the setup spends seconds negotiating the telemetry rate. Status says so; abort then lets the
    setup finish its bounded steps and the loop end at once: exit 0, "aborted", no mode
    requested, no arming, not one setpoint."""
    from pymavlink import mavutil
    control = ControlChannel()
    out: dict = {}
    port = free_udp_port()
    settings = RunSettings(link=LinkConfig(url=f"udpin:127.0.0.1:{port}"),
                           mission=missions.paper_ellipse(0.04, 60.0),
                           runner=RunnerConfig(arm=True, telemetry_timeout=60.0))
    vehicle = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1,
                                         source_component=1, dialect="ardupilotmega")
    heard: list = []
    stop = threading.Event()

    def beat():
        while not stop.wait(0.1):
            vehicle.mav.heartbeat_send(10, 3, 1, 0, 3)   # a rover, ArduPilot, MANUAL, standby
            while (msg := vehicle.recv_match(blocking=False)) is not None:
                heard.append(msg)

    beater = threading.Thread(target=beat, daemon=True)
    beater.start()
    worker = _fly_in_thread(settings, control, out)
    try:
        deadline = time.monotonic() + 30.0
        s: dict = {}
        while time.monotonic() < deadline:
            s = _status(control)
            if s["step"] == "negotiating the telemetry rate":
                break
            time.sleep(0.05)
        assert s["state"] == "setting_up" and s["mode"] == "MANUAL", s
        assert s["track_mode"] == "GUIDED", s
        assert control.submit("abort")[0]
        worker.join(120.0)
        assert not worker.is_alive()
    finally:
        stop.set()
        beater.join(2.0)
        if worker.is_alive():
            control.submit("abort")
            worker.join(60.0)
        vehicle.close()
    r = out.get("r")
    assert r is not None, out
    assert (r.reason, r.exit_code) == ("aborted", 0), r
    sent = [m for m in heard if m.get_type() in ("COMMAND_LONG", "SET_POSITION_TARGET_LOCAL_NED")]
    assert not [m for m in sent if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
    assert not [m for m in sent if m.command in (176, 400)], [m.command for m in sent]
