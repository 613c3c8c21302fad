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
from sitl_plant.testing import PlantProcess

MISSION_TEXT = 'name = "loaded"\nduration = 20\n[trajectory]\nkind = "ellipse"\nf_r = 0.12\n'


def _status(control: ControlChannel) -> dict:
    ok, text = control.submit("status", timeout=5.0)
    assert ok, text
    return json.loads(text)


def _wait_state(control, state, timeout=20.0):
    deadline = time.monotonic() + timeout
    s: dict = {}
    while time.monotonic() < deadline:
        # The loop answers once its setup (connecting, rates, parameters) is over: on a loaded
        # machine that took more than one request's 5 s (CI, 2026-12-04), so only the deadline
        # counts here; once it answers, every later _status must be answered
        ok, text = control.submit("status", timeout=max(0.1, min(5.0, deadline - time.monotonic())))
        if ok:
            s = json.loads(text)
            if s["state"] == state:
                return s
        time.sleep(0.05)
    raise AssertionError(f"never reached {state} within {timeout:g} s: {s or 'no answer'}")


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
