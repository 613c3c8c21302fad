"""Every Zenoh-using process exits by itself within 2 s of SIGTERM / SIGINT, and on its own
error paths (callback threads of an unclosed session would keep it alive forever)."""

from __future__ import annotations

import signal
import time

import pytest

from companion.bus.codec import encode, status_payload
from companion.live.events import StatusEvent
from sitl_plant.testing import PlantProcess, free_udp_port
from testbed.missions import mission_file
from testbed.zenoh_fleet import ISOLATED, Collector, Proc, endpoint, free_tcp_port, secret_file, session


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_run_with_publisher_and_queryable_exits_on_signal(tmp_path, sig):
    port = free_tcp_port()
    mission = mission_file(tmp_path / "m.toml", 60.0)
    with session(listen=[endpoint(port)]) as s:
        heard = Collector(s)
        with PlantProcess("--speedup", "2", sysid=2) as plant, \
                Proc("run", "--connect", f"udpin:127.0.0.1:{plant.port}", "--mission",
                     str(mission), "--arm", "--json", "--rate", "20",
                     "--control-secret", str(secret_file(tmp_path / "k")),
                     "--zenoh-connect", endpoint(port), *ISOLATED, tmp=tmp_path,
                     name="run") as run:
            heard.wait(lambda: len(heard.of("state")) > 5, 20.0, "state flowing")
            code, took = run.stop(sig, within=2.0)
            assert code == 0, run.stderr              # stopped the rover, then exited
            assert run.result()["hold_confirmed"]
        heard.wait(lambda: "stopped" in heard.statuses(), 2.0, "stopped status")


def test_run_exits_on_signal_before_the_vehicle_answers_and_on_its_own_errors(tmp_path):
    mission = mission_file(tmp_path / "m.toml", 5.0)
    # Nobody on the MAVLink port: SIGTERM while it waits for a heartbeat.
    with Proc("run", "--connect", f"udpin:127.0.0.1:{free_udp_port()}", "--mission",
              str(mission), *ISOLATED, tmp=tmp_path, name="wait") as run:
        time.sleep(2.0)                      # well past the session's opening
        assert run.proc.poll() is None, run.stderr
        code, _ = run.stop(signal.SIGTERM, within=2.0)
        assert code != 0
    # Its own error path: no heartbeat within 1 s is a user error (exit 2), and it exits.
    with Proc("run", "--connect", f"udpin:127.0.0.1:{free_udp_port()}", "--mission",
              str(mission), "--heartbeat-timeout", "1", *ISOLATED, tmp=tmp_path,
              name="timeout") as run:
        assert run.wait(1.0 + 8.0) == 2, run.stderr
        assert "heartbeat" in run.stderr.lower() and "Traceback" not in run.stderr


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_monitor_and_router_exit_on_signal(tmp_path, sig):
    port = free_tcp_port()
    with Proc("router", "--zenoh-listen", endpoint(port), *ISOLATED, tmp=tmp_path,
              name="router") as router:
        router.wait_line("routing", 10.0)
        with Proc("monitor", "--zenoh-mode", "client", "--zenoh-connect", endpoint(port),
                  *ISOLATED, tmp=tmp_path, name="monitor") as monitor, \
                session(mode="client", connect=[endpoint(port)]) as s:
            pub = s.declare_publisher("rover/x9/status")
            payload = encode(status_payload("x9", 1, StatusEvent("tracking", "test"), 0.0))
            # Let the monitor's subscriber callbacks run (what hangs an unclosed process):
            # publish until its table shows the vehicle.
            deadline = time.monotonic() + 10.0
            while not any(line.startswith("x9 ") for line in monitor.stdout.splitlines()):
                pub.put(payload)
                time.sleep(0.05)
                assert time.monotonic() < deadline, monitor.stderr
            code, _ = monitor.stop(sig, within=2.0)
            assert code == 0, monitor.stderr
            pub.undeclare()
        code, _ = router.stop(sig, within=2.0)
        assert code == 0 and "stopped" in router.stderr, router.stderr


def test_demo_exits_on_sigterm(tmp_path):
    port = free_tcp_port()
    with session(listen=[endpoint(port)]) as s:
        heard = Collector(s)
        with Proc("demo", "--speedup", "1", "--duration", "30", "--no-plot", "--json",
                  "--zenoh-connect", endpoint(port), *ISOLATED, tmp=tmp_path,
                  name="demo") as demo:
            heard.wait(lambda: len(heard.of("state")) > 5, 20.0, "state flowing")
            code, _ = demo.stop(signal.SIGTERM, within=2.0)
            assert code == 0, demo.stderr
            assert demo.result()["plant_exit"] == 0


def test_losing_the_router_mid_mission_disturbs_neither_the_loop_nor_the_exit(tmp_path):
    port = free_tcp_port()
    mission = mission_file(tmp_path / "m.toml", 5.0)
    with Proc("router", "--zenoh-listen", endpoint(port), *ISOLATED, tmp=tmp_path,
              name="router") as router:
        router.wait_line("routing", 10.0)
        with session(mode="client", connect=[endpoint(port)]) as s:
            heard = Collector(s)
            with PlantProcess("--speedup", "1") as plant, \
                    Proc("run", "--connect", f"udpin:127.0.0.1:{plant.port}", "--mission",
                         str(mission), "--arm", "--json", "--rate", "40", "--zenoh-mode",
                         "client", "--zenoh-connect", endpoint(port), *ISOLATED, tmp=tmp_path,
                         name="run") as run:
                heard.wait(lambda: len(heard.of("state")) > 40, 20.0, "state via the router")
                router.proc.kill()                      # the network dies mid-mission
                assert run.wait(15.0) == 0, run.stderr
                r = run.result()
    assert r["reason"] == "mission_done" and r["duration_s"] >= 4.9
    # A put that blocked on the dead link would stall the loop (and this run) for good; a
    # couple of missed cycles is what a busy shared machine costs anyway.
    assert r["missed_cycles"] <= 2 and r["sink_errors"] == 0, r
