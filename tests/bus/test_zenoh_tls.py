"""Issue 15 over real Zenoh sessions and processes on loopback: a fleet behind a router over
mutual TLS, roles held by Zenoh's access control, nothing in clear on the wire, the ``pki``
command, and start-up errors.

Outsiders are opened in *peer* mode where it matters: a peer's open succeeds even when it cannot
connect (it keeps retrying), so the test can show that it hears nothing and gets no reply,
rather than only that an open failed.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import shutil
import time
from functools import partial
from pathlib import Path

import pytest
import zenoh

from companion.bus.codec import encode, state_payload
from companion.bus.config import BusOptions
from companion.bus.control_client import control_request
from companion.bus.session import prepare
from companion.cli import main
from companion.live.events import LoopRecord
from companion.security import pki
from testbed.missions import mission_file
from testbed.process import companion_cli
from testbed.zenoh_fleet import (
    Collector,
    Proc,
    WireRecorder,
    config,
    endpoint,
    free_tcp_port,
    make_pki,
    secret_file,
    session,
    tls_endpoint,
    tls_isolated,
)

SECRET = "correct horse battery staple"
FLEET = {"router": "router", "rover1": "rover", "rover2": "rover", "rover3": "rover",
         "op": "operator", "mon": "monitor"}
REC = LoopRecord(12.345, 3.21, 1.0, 2.0, 0.3, 1.01, 2.01, 0.31, 1.1, 2.1, 0.14, 0.02,
                 1.2, 0.3, 1.25, 0.4, "GUIDED", True)


_companion = partial(companion_cli, timeout=30.0)


def _no_reply(s: zenoh.Session, vehicle: str, verb: str = "pause") -> bool:
    reply = control_request(s, vehicle, verb, secret=SECRET, timeout=1.5)
    return reply["ok"] is False and reply["message"].startswith("no reply")


def _demo(d: Path, name: str, cfg: Path, connect: str, secret: Path, tmp: Path,
          *zenoh_flags: str) -> Proc:
    return Proc("demo", "--zenoh-tls", str(d / name), "--zenoh-config", str(cfg),
                "--zenoh-connect", connect, *zenoh_flags, "--control-secret", str(secret),
                "--speedup", "1", "--duration", "60", "--no-plot", "--no-log", "--json",
                tmp=tmp, name=name)


# --------------------------------------------------------------------------- the fleet

@pytest.mark.slow   # long: started first under workers (conftest.py)
def test_a_tls_fleet_admits_only_its_certificates_each_in_its_role(tmp_path):
    d = make_pki(tmp_path / "pki", FLEET)
    other = make_pki(tmp_path / "other", {"mon": "monitor", "op": "operator"})
    secret = secret_file(tmp_path / "secret", SECRET)
    cfg = tls_isolated(tmp_path)
    port = free_tcp_port()
    router_ep = tls_endpoint(port)
    client = ["--zenoh-mode", "client"]
    as_op = ["--zenoh-tls", str(d / "op"), "--zenoh-config", str(cfg), *client,
             "--zenoh-connect", router_ep]
    with Proc("router", "--zenoh-tls", str(d / "router"), "--zenoh-listen", router_ep,
              "--zenoh-config", str(cfg), tmp=tmp_path, name="router") as router:
        router.wait_line("routing", 15.0)
        assert "access control knows 3 rover(s), 1 operator(s), 1 monitor(s)" in router.stderr
        # rover1 reaches the router through a proxy that records every byte.
        with WireRecorder(port) as wire, \
                session(config("client", connect=[router_ep], tls=(d, "mon"))) as mon, \
                _demo(d, "rover1", cfg, tls_endpoint(wire.port), secret, tmp_path,
                      *client) as rover1, \
                _demo(d, "rover2", cfg, router_ep, secret, tmp_path, *client) as rover2:
            heard = Collector(mon)
            heard.wait(lambda: {"rover1", "rover2"} <= {h.msg["vehicle_id"]
                                                       for h in heard.of("state")},
                       40.0, "state from both rovers")

            # A monitor's certificate (the command, through the router) sees every rover.
            out = _companion("monitor", "--zenoh-tls", str(d / "mon"), "--zenoh-config",
                             str(cfg), *client, "--zenoh-connect", router_ep, "--once",
                             "--json", "--wait", "1.5")
            snap = json.loads(out.stdout)
            assert {v["vehicle_id"] for v in snap["vehicles"]} == {"rover1", "rover2"}, out
            assert all(v["state_msgs"] > 10 for v in snap["vehicles"]), snap

            # No certificate, or one from another CA: no connection, so nothing heard and no
            # reply, even with the right secret.
            with pytest.raises(zenoh.ZError):
                zenoh.open(config("client", connect=[endpoint(port)]))      # plain TCP
            with pytest.raises(zenoh.ZError):
                zenoh.open(config("client", connect=[router_ep], tls=(other, "mon")))
            with session(config("peer", connect=[endpoint(port)])) as plain, \
                    session(config("peer", connect=[router_ep], tls=(other, "mon"))) as alien:
                ears = [Collector(plain), Collector(alien)]
                assert _no_reply(plain, "rover1") and _no_reply(alien, "rover1")
                time.sleep(0.5)
                assert [len(e.heard) for e in ears] == [0, 0]
            refused = _companion("control", "rover1", "pause", "--secret", str(secret),
                                 "--zenoh-tls", str(other / "op"), "--zenoh-config", str(cfg),
                                 *client, "--zenoh-connect", router_ep)
            assert refused.returncode == 2 and "cannot open the Zenoh session" in refused.stderr

            # A rover's certificate: its own key only, and no control (the secret is right).
            with session(config("client", connect=[router_ep], tls=(d, "rover3"))) as rogue:
                time.sleep(0.3)
                spoof = state_payload("rover1", -1, 1, REC, time.time())
                rogue.put("rover/rover1/state", encode(spoof))
                rogue.put("rover/rover3/state", encode(state_payload("rover3", 1, 1, REC,
                                                                      time.time())))
                assert _no_reply(rogue, "rover1") and _no_reply(rogue, "rover2", "abort")
                heard.wait(lambda: heard.of("state", "rover3"), 3.0, "rover3's own state")
                assert not [h for h in heard.of("state", "rover1") if h.msg["seq"] == -1]
            # A monitor's certificate may not steer either.
            assert _no_reply(mon, "rover1")
            assert "paused" not in heard.statuses("rover1")

            # An operator's certificate pauses and resumes; the secret is still checked.
            for verb, event in (("pause", "paused"), ("resume", "resumed")):
                out = _companion("control", "rover1", verb, "--secret", str(secret), *as_op)
                assert out.returncode == 0 and json.loads(out.stdout)["ok"], out
                heard.wait(lambda event=event: event in heard.statuses("rover1"), 5.0, event)
            with session(config("client", connect=[router_ep], tls=(d, "op"))) as op:
                wrong = control_request(op, "rover1", "pause", secret="not the secret",
                                        timeout=3.0)
                assert wrong["ok"] is False and "wrong secret" in wrong["message"], wrong
            assert heard.statuses("rover1")[-2:] == ["paused", "resumed"]
            assert "paused" not in heard.statuses("rover2")

            # SIGTERM: each demo stops its rover and its plant, and exits 0.
            assert [p.stop(within=5.0)[0] for p in (rover1, rover2)] == [0, 0]
            relayed = wire.data
        # The wire between rover1 and the router: plenty relayed, none of it readable.
        assert len(relayed) > 50_000, len(relayed)
        for plain_text in (SECRET.encode(), b'"schema":"pzc-rover/state/1"', b"pzc-rover",
                           b"rover/rover1", b"GUIDED"):
            assert plain_text not in relayed, plain_text
        assert router.stop()[0] == 0


def test_the_wire_recorder_would_see_plain_tcp_and_sees_nothing_over_tls(tmp_path):
    """The same exchange (a state put, a control request with its secret) through the proxy,
    in clear and over mutual TLS: the first shows the check can fail."""
    d = make_pki(tmp_path / "pki", FLEET)
    found = {}
    for tls in (False, True):
        port = free_tcp_port()
        ep = tls_endpoint(port) if tls else endpoint(port)
        creds = {"router": (d, "router"), "rover": (d, "rover1"), "op": (d, "op")} if tls \
            else {"router": None, "rover": None, "op": None}
        with session(config("router", listen=[ep], tls=creds["router"])), \
                WireRecorder(port) as wire:
            via = tls_endpoint(wire.port) if tls else endpoint(wire.port)
            with session(config("client", connect=[via], tls=creds["rover"])) as rover, \
                    session(config("client", connect=[ep], tls=creds["op"])) as op:
                q = rover.declare_queryable("rover/rover1/control",
                                            lambda query: query.reply(query.key_expr, b"ok"))
                time.sleep(0.3)
                rover.put("rover/rover1/state", encode(state_payload("rover1", 1, 1, REC, 0.0)))
                replies = list(op.get("rover/rover1/control?verb=pause", attachment=SECRET,
                                      timeout=2.0))
                assert len(replies) == 1 and replies[0].ok is not None
                q.undeclare()
            data = wire.data
        found[tls] = {SECRET.encode() in data, b'"schema":"pzc-rover/state/1"' in data}
    assert found[False] == {True}, "the proxy should see plain TCP in clear"
    assert found[True] == {False}, "nothing in clear over TLS"


def test_a_peer_checks_that_the_certificate_names_the_host_it_dialled(tmp_path):
    """Same CA, right role, but issued for another host: the connecting side refuses it."""
    d = make_pki(tmp_path / "pki", {"mon": "monitor"})
    pki.issue(d, "far", "router", sans=["far.example"])
    pki.issue(d, "near", "router")
    for name, opens in (("far", False), ("near", True)):
        port = free_tcp_port()
        with session(config("router", listen=[tls_endpoint(port)], tls=(d, name))):
            try:
                zenoh.open(config("client", connect=[tls_endpoint(port)], tls=(d, "mon"))).close()
                opened = True
            except zenoh.ZError:
                opened = False
        assert opened is opens, name


def test_a_rovers_own_session_holds_its_role_without_a_router(tmp_path):
    """A demo listening as a peer (no router): peers with the fleet's certificates connect
    straight to it, and the rover's own access control decides."""
    d = make_pki(tmp_path / "pki", FLEET)
    secret = secret_file(tmp_path / "secret", SECRET)
    cfg = tls_isolated(tmp_path)
    port = free_tcp_port()
    ep = tls_endpoint(port)
    with Proc("demo", "--zenoh-tls", str(d / "rover1"), "--zenoh-config", str(cfg),
              "--zenoh-listen", ep, "--control-secret", str(secret), "--speedup", "1",
              "--duration", "60", "--no-plot", "--no-log", tmp=tmp_path, name="rover1") as demo, \
            session(config("peer", connect=[ep], tls=(d, "mon"))) as mon, \
            session(config("peer", connect=[ep], tls=(d, "rover2"))) as rover2:
        heard, nosy = Collector(mon), Collector(rover2)
        heard.wait(lambda: heard.of("state", "rover1"), 40.0, "rover1's state")
        assert _no_reply(rover2, "rover1") and _no_reply(mon, "rover1")
        assert nosy.heard == [] and "paused" not in heard.statuses("rover1")
        # Through a Zenoh config file instead of --zenoh-tls: the same checks and rules.
        file_cfg = tmp_path / "op.json5"
        file_cfg.write_text(json.dumps({
            "mode": "peer", "scouting": {"multicast": {"enabled": False}},
            "listen": {"endpoints": []}, "connect": {"endpoints": [ep]},
            "transport": {"link": {"tls": {"root_ca_certificate": str(d / "ca.pem"),
                                           "connect_certificate": str(d / "op.pem"),
                                           "connect_private_key": str(d / "op.key")}}}}))
        out = _companion("monitor", "--once", "--json", "--wait", "1",
                         "--zenoh-config", str(file_cfg))      # an operator may watch
        assert out.returncode == 0, out
        assert [v["vehicle_id"] for v in json.loads(out.stdout)["vehicles"]] == ["rover1"]
        out = _companion("control", "rover1", "pause", "--secret", str(secret),
                         "--zenoh-config", str(file_cfg))
        assert out.returncode == 0 and json.loads(out.stdout)["ok"], out
        heard.wait(lambda: "paused" in heard.statuses("rover1"), 5.0, "paused")
        out = _companion("router", "--zenoh-config", str(file_cfg))
        assert out.returncode == 2 and f"{file_cfg} (transport/link/tls): " in out.stderr
        assert "needs a router's" in out.stderr and len(out.stderr.splitlines()) == 1
        assert demo.stop(within=5.0)[0] == 0


def test_a_rovers_own_session_cannot_publish_under_another_name(tmp_path):
    """The session ``companion run --zenoh-tls DIR/rover2`` opens, connected straight to a
    monitor (no router to filter): even if its code tried, only rover2's keys leave it."""
    d = make_pki(tmp_path / "pki", FLEET)
    port = free_tcp_port()
    with session(config("peer", listen=[tls_endpoint(port)], tls=(d, "mon"))) as mon:
        heard = Collector(mon)
        own = prepare(BusOptions(tls=str(d / "rover2"), roles=("rover",),
                                 connect=(tls_endpoint(port),),
                                 config_file=str(tls_isolated(tmp_path))))
        assert own.identity.name == "rover2" and own.identity.role == "rover"
        with session(own.config) as rover2:
            time.sleep(0.5)
            for vid in ("rover1", "rover2", "rover1"):
                rover2.put(f"rover/{vid}/state", encode(state_payload(vid, 1, 1, REC, 0.0)))
            heard.wait(lambda: heard.of("state", "rover2"), 3.0, "rover2's own state")
            time.sleep(0.3)
        assert [h.key for h in heard.heard] == ["rover/rover2/state"]


@pytest.mark.slow
def test_a_fleet_given_only_the_router_and_tls_hears_itself_in_the_default_mode(tmp_path):
    """Issue 43, item 9: a rover, a monitor and an operator, each given only its certificate and
    the router's endpoint (no --zenoh-mode): they reach each other. A peer over mutual TLS
    listens nowhere, and Zenoh's router relays nothing between two peers, so without a listener
    each is made a client (and says so)."""
    d = make_pki(tmp_path / "pki", FLEET)
    secret = secret_file(tmp_path / "secret", SECRET)
    cfg = tls_isolated(tmp_path)
    router_ep = tls_endpoint(free_tcp_port())

    def who(name: str) -> list[str]:
        return ["--zenoh-tls", str(d / name), "--zenoh-config", str(cfg),
                "--zenoh-connect", router_ep]

    # A client needs its router: with none yet, one line and exit 2, not a silent wait.
    early = _companion("monitor", *who("mon"), "--once", "--json", "--wait", "1")
    assert early.returncode == 2 and len(early.stderr.splitlines()) == 1, early
    assert "cannot open the Zenoh session" in early.stderr and "Traceback" not in early.stderr
    with Proc("router", "--zenoh-tls", str(d / "router"), "--zenoh-listen", router_ep,
              "--zenoh-config", str(cfg), tmp=tmp_path, name="router") as router:
        router.wait_line("routing", 15.0)
        with _demo(d, "rover1", cfg, router_ep, secret, tmp_path) as rover1:
            rover1.wait_line("mode client over mutual TLS", 20.0)
            rover1.wait_line("publishing rover/rover1/state", 40.0)
            out = _companion("monitor", *who("mon"), "--once", "--json", "--wait", "2")
            assert out.returncode == 0, out
            snap = json.loads(out.stdout)
            assert [v["vehicle_id"] for v in snap["vehicles"]] == ["rover1"], snap
            assert snap["vehicles"][0]["state_msgs"] > 10, snap
            out = _companion("control", "rover1", "status", "--secret", str(secret), *who("op"))
            assert out.returncode == 0 and json.loads(out.stdout)["ok"], out
            assert rover1.stop(within=5.0)[0] == 0
        assert router.stop()[0] == 0


def test_only_a_session_with_nowhere_to_listen_and_no_chosen_mode_becomes_a_client(tmp_path):
    """Over mutual TLS, a peer that connects somewhere and listens nowhere would be heard by no
    other peer: it becomes a client. A mode the flags or the file chose is kept, so is a peer
    that listens, and a plain session is left as it was."""
    d = make_pki(tmp_path / "pki", FLEET)
    iso = str(tls_isolated(tmp_path))
    peer_file = tmp_path / "peer.json5"
    peer_file.write_text('{ mode: "peer", scouting: { multicast: { enabled: false } }, '
                         'listen: { endpoints: [] } }')
    router, own = (tls_endpoint(free_tcp_port()) for _ in range(2))
    tls = {"tls": str(d / "rover1"), "roles": ("rover",)}
    cases = [
        (dict(connect=(router,), config_file=iso, **tls), "client"),
        (dict(connect=(router,), config_file=iso, mode="peer", **tls), "peer"),
        (dict(connect=(router,), config_file=str(peer_file), **tls), "peer"),
        (dict(connect=(router,), listen=(own,), config_file=iso, **tls), "peer"),
        (dict(config_file=iso, **tls), "peer"),
        (dict(connect=(endpoint(free_tcp_port()),), config_file=iso), "peer"),
    ]
    for kwargs, mode in cases:
        prepared = prepare(BusOptions(**kwargs))
        # null: Zenoh's default, a peer
        assert (json.loads(prepared.config.get_json("mode")) or "peer") == mode, kwargs
        assert (prepared.note is not None) == (mode == "client"), kwargs


# --------------------------------------------------------------------------- pki and errors

def _main(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err.strip()


def test_pki_init_issue_show(tmp_path, capsys):
    d = tmp_path / "site"
    code, out, _ = _main(capsys, "pki", "init", str(d))
    assert code == 0 and "ca.pem" in out
    assert (d.stat().st_mode & 0o777) == 0o700 and ((d / "ca.key").stat().st_mode & 0o777) == 0o600
    code, _, err = _main(capsys, "pki", "init", str(d))
    assert code == 2 and "already holds a CA" in err
    for name, role in (("rover7", "rover"), ("alice", "operator"), ("wall", "monitor")):
        code, out, _ = _main(capsys, "pki", "issue", str(d), name, "--role", role)
        assert code == 0 and f"{role} '{name}'" in out, out
        assert ((d / f"{name}.key").stat().st_mode & 0o777) == 0o600
    code, _, _ = _main(capsys, "pki", "issue", str(d), "hub", "--role", "router",
                       "--san", "hub.site.lan", "--san", "10.0.0.2", "--days", "30")
    assert code == 0
    code, out, _ = _main(capsys, "pki", "show", str(d / "hub"), "--json")
    shown = json.loads(out)
    assert code == 0 and shown["subject"] == "hub" and shown["role"] == "router"
    assert shown["names"] == ["hub", "hub.site.lan", "10.0.0.2"] and shown["valid"]
    assert 29 < shown["days_left"] <= 30
    code, out, _ = _main(capsys, "pki", "show", str(d / "rover7"))
    assert code == 0 and "role      rover" in out and "subject   rover7" in out
    assert "localhost, 127.0.0.1" in out and "status    ok" in out
    # Refusals: one line each, exit 2.
    for argv, needle in ((["issue", str(d), "rover7", "--role", "rover"], "--force"),
                         (["issue", str(d), "a*b", "--role", "rover"], "name 'a*b'"),
                         (["issue", str(d), "x", "--role", "rover", "--san", "no way"], "--san"),
                         (["issue", str(tmp_path / "none"), "x", "--role", "rover"], "no CA"),
                         (["show", str(d / "ghost")], "no such file")):
        code, _, err = _main(capsys, "pki", *argv)
        assert code == 2 and needle in err and len(err.splitlines()) == 1, (argv, err)
    (d / "ca.key").chmod(0o644)
    code, _, err = _main(capsys, "pki", "issue", str(d), "y", "--role", "rover")
    assert code == 2 and "chmod 600" in err, err
    # Another CA's certificate shown against this CA: not valid here (exit 1).
    other = make_pki(tmp_path / "other", {"bob": "operator"})
    shutil.copy(other / "bob.pem", d / "bob.pem")
    code, out, _ = _main(capsys, "pki", "show", str(d / "bob"))
    assert code == 1 and "not issued by the CA" in out


def _bad_cases(d: Path, tmp: Path) -> list[tuple[list[str], str]]:
    """(command line, what the one line must say) for each start-up error."""
    past = pki.utcnow() - dt.timedelta(days=30)
    pki.issue(d, "old", "monitor", days=10, now=past)
    pki.issue(d, "soon", "monitor", now=pki.utcnow() + dt.timedelta(days=2))
    pki.issue(d, "loose", "monitor")
    (d / "loose.key").chmod(0o644)
    pki.issue(d, "keyless", "monitor")
    (d / "keyless.key").unlink()
    if os.geteuid() != 0:       # root reads a mode-000 file anyway
        pki.issue(d, "unreadable", "monitor")
        (d / "unreadable.key").chmod(0o000)
    other = make_pki(tmp / "other", {"alien": "monitor"})
    shutil.copy(other / "alien.pem", d / "alien.pem")
    shutil.copy(other / "alien.key", d / "alien.key")
    pki.issue(d, "swapped", "monitor")
    shutil.copy(d / "mon.key", d / "swapped.key")
    (d / "garbage.pem").write_text("-----BEGIN CERTIFICATE-----\nnope\n")
    shutil.copy(d / "mon.key", d / "garbage.key")
    mission = mission_file(tmp / "m.toml", 3.0)
    cfg = str(tls_isolated(tmp))
    mon = ["monitor", "--once", "--wait", "0.1", "--zenoh-config", cfg, "--zenoh-tls"]
    run = ["run", "--connect", "udpin:127.0.0.1:1", "--mission", str(mission),
           "--zenoh-config", cfg, "--zenoh-tls"]
    ctl = ["control", "rover1", "status", "--secret", str(secret_file(tmp / "s", SECRET)),
           "--zenoh-config", cfg, "--zenoh-tls"]
    return [
        (mon + [str(d / "keyless")], "keyless.key: no such file"),
        *([(mon + [str(d / "unreadable")], "unreadable.key: cannot read")]
          if os.geteuid() != 0 else []),
        (mon + [str(d / "loose")], "other users can access the private key (mode 0644)"),
        (mon + [str(d / "alien")], "was not issued by the CA in"),
        (mon + [str(d / "old")], "old.pem expired on"),
        (mon + [str(d / "soon")], "not valid before"),
        (mon + [str(d / "swapped")], "swapped.key is not the key of"),
        (mon + [str(d / "garbage")], "garbage.pem: not a PEM certificate"),
        (mon + [str(tmp / "nowhere" / "mon")], "no CA certificate"),
        (mon + [str(d / "rover1")], "is a rover's certificate (rover1); this command needs a "
                                    "monitor's or an operator's"),
        (ctl + [str(d / "mon")], "is a monitor's certificate (mon); this command needs an "
                                 "operator's"),
        (run + [str(d / "op")], "needs a rover's"),
        (["router", "--zenoh-config", cfg, "--zenoh-tls", str(d / "rover1")], "needs a router's"),
        (run + [str(d / "rover1"), "--vehicle-id", "rover2"], "publishes only under its own name"),
        (ctl + [str(d / "op"), "--zenoh-connect", "tcp/127.0.0.1:7447"],
         "--zenoh-connect tcp/127.0.0.1:7447: with mutual TLS every endpoint must be tls/"),
        (["monitor", "--once", "--zenoh-tls", str(d / "mon")], "listen/endpoints tcp/"),
    ]


def test_start_up_errors_are_one_line_and_exit_2(tmp_path, capsys):
    # A CA from 60 days ago, so that it can have issued a certificate now expired.
    d = make_pki(tmp_path / "pki", FLEET, ca_since=pki.utcnow() - dt.timedelta(days=60))
    for argv, needle in _bad_cases(d, tmp_path):
        code, _, err = _main(capsys, *argv)
        assert code == 2 and needle in err and len(err.splitlines()) == 1, (argv, err)
        assert "Traceback" not in err and ".rs:" not in err
