"""Issue 5 over real Zenoh sessions on loopback (multicast scouting off, free ports): the state
and status streams of a SITL run, every control verb, refusals, and bad input."""

from __future__ import annotations

import math
import time
from itertools import pairwise
from pathlib import Path

import pytest

from companion.bus.codec import STATE_SCHEMA, STATUS_SCHEMA
from companion.bus.control_client import control_request
from companion.cli import main
from sitl_plant.testing import PlantProcess
from testbed.missions import mission_file
from testbed.zenoh_fleet import ISOLATED, Collector, Proc, endpoint, free_tcp_port, secret_file, session

STATE_FIELDS = {"schema": str, "vehicle_id": str, "seq": int, "every": int, "sent_at": float,
                "vehicle_time": float, "mission_time": float, "pose": dict, "filtered": dict,
                "reference": dict, "error": dict, "setpoint": dict, "mode": str, "armed": bool}
NESTED = {"pose": ("x", "y", "yaw"), "filtered": ("x", "y", "yaw"), "reference": ("x", "y"),
          "error": ("position", "yaw"), "setpoint": ("speed", "yaw_rate", "ux", "uy")}


def _check_state(msg: dict) -> None:
    for name, kind in STATE_FIELDS.items():
        assert isinstance(msg[name], kind) or (kind is float and isinstance(msg[name], int)), \
            (name, msg[name])
    for group, names in NESTED.items():
        assert set(msg[group]) == set(names), group
        assert all(math.isfinite(msg[group][n]) for n in names), (group, msg[group])
    assert msg["schema"] == STATE_SCHEMA


def test_state_and_status_of_a_sitl_run_follow_the_schema(tmp_path):
    port = free_tcp_port()
    mission = mission_file(tmp_path / "m.toml", 3.0)
    with session(listen=[endpoint(port)]) as s:
        heard = Collector(s)
        with PlantProcess("--speedup", "4", "--d-cen", "0.3", sysid=7) as plant, \
                Proc("run", "--connect", f"udpin:127.0.0.1:{plant.port}", "--sysid", "7",
                     "--mission", str(mission), "--arm", "--json", "--rate", "40",
                     "--state-every", "2", "--zenoh-connect", endpoint(port), *ISOLATED,
                     tmp=tmp_path, name="run") as run:
            assert run.wait(30.0) == 0, run.stderr
            result = run.result()
            # Control is off unless enabled: nobody answers on the control key.
            reply = control_request(s, "rover7", "status", secret="x" * 10, timeout=0.5)
            assert not reply["ok"] and "no reply" in reply["message"]
        heard.wait(lambda: "stopped" in heard.statuses(), 3.0, "stopped status")
        assert not heard.bad
        assert heard.statuses() == ["connected", "gnss", "tracking", "mission_done", "stopped"]
        statuses = [h.msg for h in heard.of("status")]
        assert all(m["schema"] == STATUS_SCHEMA and m["vehicle_id"] == "rover7" for m in statuses)
        assert [m["seq"] for m in statuses] == [1, 2, 3, 4, 5]
        assert statuses[0]["detail"]["sysid"] == 7
        assert statuses[-1]["reason"] == "mission_done" and statuses[-1]["detail"]["exit_code"] == 0
        states = heard.of("state")
        assert {h.key for h in states} == {"rover/rover7/state"}
        for h in states:
            _check_state(h.msg)
        # Decimated by 2: every other control cycle, none lost on loopback.
        seqs = [h.msg["seq"] for h in states]
        assert seqs == list(range(1, 2 * len(seqs), 2)), seqs[:10]
        assert abs(len(states) - result["cycles"] / 2) <= 1, (len(states), result["cycles"])
        times = [h.msg["vehicle_time"] for h in states]
        assert all(b > a for a, b in pairwise(times))
        assert all(h.msg["mode"] == "GUIDED" and h.msg["armed"] for h in states)
        assert states[-1].msg["mission_time"] > 2.8
        assert states[-1].msg["error"]["position"] < 0.5     # it really tracked
        assert result["sink_errors"] == 0 and result["reason"] == "mission_done"


MISSION_TEXT = ('name = "loaded"\nframe = "start"\nduration = 20\n'
                '[trajectory]\nkind = "ellipse"\nf_r = 0.12\n')


def test_every_control_verb_and_every_refusal(tmp_path, capsys):
    port = free_tcp_port()
    secret = "correct horse battery staple"
    key_file = secret_file(tmp_path / "secret", secret)
    mission = mission_file(tmp_path / "m.toml", 60.0, name="first")
    with session(listen=[endpoint(port)]) as s:
        heard = Collector(s)

        def ask(verb, payload=None, key=secret):
            return control_request(s, "alpha", verb, secret=key, payload=payload, timeout=3.0)

        def status():
            r = ask("status")
            assert r["ok"], r
            return r["status"]

        with PlantProcess("--speedup", "2", "--d-cen", "0.3", sysid=4) as plant, \
                Proc("run", "--connect", f"udpin:127.0.0.1:{plant.port}", "--mission",
                     str(mission), "--arm", "--json", "--rate", "20", "--vehicle-id", "alpha",
                     "--control-secret", str(key_file), "--zenoh-connect", endpoint(port),
                     *ISOLATED, tmp=tmp_path, name="run") as run:
            heard.wait(lambda: "tracking" in heard.statuses("alpha"), 20.0, "tracking")
            assert status()["state"] == "tracking"
            # Refused or malformed: an error reply each, and nothing changes.
            refusals = [
                (ask("pause", key=None), "no secret"),
                (ask("pause", key="wrong secret!"), "wrong secret"),
                (ask("pause", key=secret[:-1]), "wrong secret"),
                (ask("jump"), "unknown verb"),
                (ask(""), "no verb"),
                (ask("pause", payload="now"), "takes no payload"),
                (ask("load-mission", payload=MISSION_TEXT), "pause first"),
                (ask("load-mission", payload=b"\xff\xfe name"), "not UTF-8"),
                (ask("load-mission"), "needs the mission"),
                (ask("start"), "cannot start while tracking"),
            ]
            for reply, why in refusals:
                assert reply["ok"] is False and why in reply["message"], (why, reply)
                assert reply["schema"] == "pzc-rover/control-reply/1"
            n_states = len(heard.of("state"))
            t0 = status()["mission_time"]
            time.sleep(0.6)
            s1 = status()
            assert s1["state"] == "tracking" and s1["mission_time"] > t0 + 0.5   # it went on
            assert s1["mission"] == "first"
            assert len(heard.of("state")) > n_states
            # pause / resume
            assert ask("pause")["ok"]
            t_paused = status()["mission_time"]
            time.sleep(0.3)
            assert status()["mission_time"] == t_paused                     # clock stands still
            bad = ask("load-mission", payload='name = "x"\n[trajectory]\nkind = "nope"\n')
            assert not bad["ok"] and "trajectory.kind" in bad["message"], bad
            assert status()["mission"] == "first"
            # A file name on the companion's machine is not read for a remote operator.
            shipped = str(Path(__file__).resolve().parents[2] / "missions" / "circle.toml")
            by_path = ask("load-mission", payload=shipped)
            assert not by_path["ok"] and status()["mission"] == "first", by_path
            assert ask("resume")["ok"]
            time.sleep(0.3)
            assert status()["mission_time"] > t_paused
            # load-mission (while paused), then start
            assert ask("pause")["ok"]
            loaded = ask("load-mission", payload=MISSION_TEXT)
            assert loaded["ok"], loaded
            s2 = status()
            assert (s2["state"], s2["mission"], s2["mission_time"]) == ("ready", "loaded", 0.0)
            assert ask("start")["ok"]
            heard.wait(lambda: status()["mission_time"] > 0.2, 5.0, "tracking the new mission")
            # The operator's command line: `companion control` (in this process).
            cli = ["control", "alpha", "--zenoh-connect", endpoint(port), *ISOLATED]
            wrong = secret_file(tmp_path / "wrong", "not the secret at all")
            code, _ = _main(capsys, *cli[:2], "status", "--secret", str(wrong), *cli[2:])
            assert code == 1
            code, err = _main(capsys, *cli[:2], "status", "--secret", str(key_file), *cli[2:])
            assert code == 0, err
            # abort: stop and HOLD now
            code, err = _main(capsys, *cli[:2], "abort", "--secret", str(key_file), *cli[2:])
            assert code == 0, err
            assert run.wait(10.0) == 0, run.stderr
            result = run.result()
        heard.wait(lambda: "stopped" in heard.statuses("alpha"), 3.0, "stopped")
    assert result["reason"] == "aborted" and result["hold_confirmed"]
    assert result["mission"] == "loaded"
    kinds = heard.statuses("alpha")
    assert kinds == ["connected", "gnss", "tracking", "paused", "resumed", "paused",
                     "mission_loaded", "tracking", "stopped"], kinds


def _main(capsys, *argv) -> tuple[int, str]:
    code = main(list(argv))
    err = capsys.readouterr().err.strip()
    return code, err


@pytest.mark.parametrize("flags, needle", [
    (["--zenoh-connect", "nonsense"], "--zenoh-connect nonsense"),
    (["--zenoh-listen", "tcp/8.8.8.8:80"], "--zenoh-listen tcp/8.8.8.8:80"),
    (["--zenoh-config", "/nonexistent/z.json5"], "--zenoh-config /nonexistent/z.json5: no such"),
    (["--vehicle-id", "a/b"], "--vehicle-id 'a/b'"),
    (["--control-secret", "/nonexistent/secret"], "--control-secret /nonexistent/secret: no such"),
])
def test_bad_zenoh_input_is_one_line_and_exit_2(tmp_path, capsys, flags, needle):
    mission = mission_file(tmp_path / "m.toml", 3.0)
    code, err = _main(capsys, "run", "--connect", "udpin:127.0.0.1:1", "--mission",
                      str(mission), *ISOLATED, *flags)
    assert code == 2 and needle in err and len(err.splitlines()) == 1, err
    assert "Traceback" not in err and ".rs:" not in err


def test_bad_config_file_and_shared_secret_file_are_refused(tmp_path, capsys):
    mission = mission_file(tmp_path / "m.toml", 3.0)
    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: 3 ")
    code, err = _main(capsys, "run", "--mission", str(mission), "--zenoh-config", str(bad))
    assert code == 2 and f"--zenoh-config {bad}: not a valid Zenoh config" in err, err
    assert len(err.splitlines()) == 1
    code, err = _main(capsys, "monitor", "--once", "--zenoh-config", str(bad))
    assert code == 2 and str(bad) in err, err
    shared = secret_file(tmp_path / "secret")
    shared.chmod(0o640)
    code, err = _main(capsys, "run", "--mission", str(mission), *ISOLATED,
                      "--control-secret", str(shared))
    assert code == 2 and "chmod 600" in err and len(err.splitlines()) == 1, err
    short = secret_file(tmp_path / "short", "abc")
    code, err = _main(capsys, "demo", "--no-plot", *ISOLATED, "--control-secret", str(short))
    assert code == 2 and "at least 8 bytes" in err, err
    code, err = _main(capsys, "router", "--zenoh-listen", "tcp/8.8.8.8:80", *ISOLATED)
    assert code == 2 and "tcp/8.8.8.8:80" in err and len(err.splitlines()) == 1, err


def test_failsafe_and_recovery_are_published_with_reasons(tmp_path):
    import signal
    port = free_tcp_port()
    mission = mission_file(tmp_path / "m.toml", 60.0)
    # This companion takes its Zenoh settings from a config file (--zenoh-config) alone.
    zconf = tmp_path / "zenoh.json5"
    zconf.write_text('{ mode: "peer", scouting: { multicast: { enabled: false } }, '
                     f'connect: {{ endpoints: ["{endpoint(port)}"] }}, '
                     'listen: { endpoints: ["tcp/127.0.0.1:0"] } }')
    with session(listen=[endpoint(port)]) as s:
        heard = Collector(s)
        with PlantProcess("--speedup", "1", "--d-cen", "0.3", sysid=5) as plant, \
                Proc("run", "--connect", f"udpin:127.0.0.1:{plant.port}", "--mission",
                     str(mission), "--arm", "--json", "--rate", "20",
                     "--zenoh-config", str(zconf), tmp=tmp_path, name="run") as run:
            heard.wait(lambda: len(heard.of("state")) > 5, 20.0, "state flowing")
            plant.proc.send_signal(signal.SIGSTOP)          # the vehicle goes silent
            try:
                heard.wait(lambda: "failsafe" in heard.statuses(), 5.0, "failsafe status")
            finally:
                plant.proc.send_signal(signal.SIGCONT)
            heard.wait(lambda: "resumed" in heard.statuses(), 10.0, "resumed status")
            n = len(heard.of("state"))
            heard.wait(lambda: len(heard.of("state")) > n + 5, 10.0, "tracking again")
            code, _ = run.stop(signal.SIGTERM)
            assert code == 0, run.stderr
        heard.wait(lambda: "stopped" in heard.statuses(), 2.0, "stopped status")
    by_kind = {h.msg["kind"]: h.msg for h in heard.of("status")}
    assert "telemetry stale" in by_kind["failsafe"]["reason"], by_kind["failsafe"]
    assert by_kind["resumed"]["reason"] == "telemetry back"
    assert by_kind["stopped"]["reason"] == "SIGTERM"
    assert heard.statuses()[:5] == ["connected", "gnss", "tracking", "failsafe", "resumed"]


def test_no_zenoh_opens_no_session(tmp_path, capsys):
    """--no-zenoh: even a broken Zenoh config is never read; what fails is the MAVLink side."""
    from sitl_plant.testing import free_udp_port
    mission = mission_file(tmp_path / "m.toml", 3.0)
    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: 3 ")
    argv = ["run", "--connect", f"udpin:127.0.0.1:{free_udp_port()}", "--mission", str(mission),
            "--heartbeat-timeout", "0.5", "--zenoh-config", str(bad)]
    code, err = _main(capsys, *argv)
    assert code == 2 and "not a valid Zenoh config" in err, err
    code, err = _main(capsys, *argv, "--no-zenoh")
    assert code == 2 and "Zenoh" not in err and "heartbeat" in err.lower(), err
