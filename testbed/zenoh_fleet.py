"""Helpers for tests with real Zenoh sessions on loopback: isolated configs (multicast scouting
off, explicit endpoints, free ports), a subscriber that keeps what it hears, and process helpers
that always stop what they start; for mutual TLS, a fleet's certificates, TLS session configs
and a TCP proxy that records every byte it relays."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh

from companion.bus.codec import decode
from sitl_plant.testing import free_port
from testbed.missions import mission_file
from testbed.process import ROOT, with_log_dir

ISOLATED = ["--no-zenoh-scouting"]


def free_tcp_port() -> int:
    return free_port(socket.SOCK_STREAM)


def endpoint(port: int) -> str:
    return f"tcp/127.0.0.1:{port}"


def tls_endpoint(port: int) -> str:
    return f"tls/127.0.0.1:{port}"


def config(mode: str = "peer", listen: list[str] | None = None,
           connect: list[str] | None = None, tls: tuple[Path, str] | None = None
           ) -> zenoh.Config:
    """``tls=(DIR, NAME)``: mutual TLS with DIR/NAME.pem / .key and DIR/ca.pem, written here
    by hand (no access control): a session the project's code did not configure."""
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(mode))
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("listen/endpoints", json.dumps(listen or []))
    c.insert_json5("connect/endpoints", json.dumps(connect or []))
    if tls is not None:
        d, name = tls
        c.insert_json5("transport/link/tls", json.dumps({
            "root_ca_certificate": str(d / "ca.pem"), "enable_mtls": True,
            "verify_name_on_connect": True,
            "listen_certificate": str(d / f"{name}.pem"),
            "listen_private_key": str(d / f"{name}.key"),
            "connect_certificate": str(d / f"{name}.pem"),
            "connect_private_key": str(d / f"{name}.key")}))
    return c


@contextlib.contextmanager
def session(config_: zenoh.Config | None = None, **kwargs) -> Iterator[zenoh.Session]:
    """A session that is closed on every path out (callbacks would otherwise hang the exit)."""
    s = zenoh.open(config_ if config_ is not None else config(**kwargs))
    try:
        yield s
    finally:
        s.close()


# --------------------------------------------------------------------------- mutual TLS

# What conftest's $ZENOH_CONFIG is for plain sessions, for TLS ones: no listener unless a flag
# says (the plain file's tcp listener would be refused: nothing in clear).
TLS_ISOLATED = """{
  scouting: { multicast: { enabled: false } },
  listen: { endpoints: [] },
  connect: { endpoints: [] },
}
"""


def tls_isolated(tmp: Path) -> Path:
    path = tmp / "tls-isolated.json5"
    path.write_text(TLS_ISOLATED)
    return path


def make_pki(d: Path, members: dict[str, str], ca_since=None) -> Path:
    """A CA in ``d`` (valid from ``ca_since``, default now) and a certificate per
    ``{name: role}``: the library ``companion pki`` calls; the command is tested on its own."""
    from companion.security import pki
    pki.init_ca(d, now=ca_since)
    for name, role in members.items():
        pki.issue(d, name, role)
    return d


class WireRecorder:
    """A TCP proxy on a free loopback port to ``target``: relays every connection both ways
    and keeps every byte it relays, to check what crosses the wire."""

    def __init__(self, target_port: int):
        self.target = ("127.0.0.1", target_port)
        self.port = free_tcp_port()
        self._lock = threading.Lock()
        self._data = bytearray()
        self._socks: list[socket.socket] = []
        self._server = socket.create_server(("127.0.0.1", self.port))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._accept, daemon=True)

    @property
    def data(self) -> bytes:
        with self._lock:
            return bytes(self._data)

    def __enter__(self) -> WireRecorder:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._server.close()
        with self._lock:
            socks = list(self._socks)
        for sock in socks:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()
        self._thread.join(2.0)

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                down, _ = self._server.accept()
            except OSError:
                return
            try:
                up = socket.create_connection(self.target, timeout=5.0)
            except OSError:
                down.close()
                continue
            up.settimeout(None)
            with self._lock:
                self._socks += [down, up]
            for a, b in ((down, up), (up, down)):
                threading.Thread(target=self._pump, args=(a, b), daemon=True).start()

    def _pump(self, src: socket.socket, dst: socket.socket) -> None:
        while True:
            try:
                chunk = src.recv(65536)
                if not chunk:
                    break
                with self._lock:
                    self._data += chunk
                dst.sendall(chunk)
            except OSError:
                break
        for sock in (src, dst):
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass


@dataclass
class Heard:
    rx: float          # monotonic
    key: str
    msg: dict[str, Any]


class Collector:
    """Callback subscriber on ``rover/*/state`` and ``rover/*/status``; decodes with the schema
    check (a payload that fails it is kept in ``bad``)."""

    def __init__(self, s: zenoh.Session, key: str = "rover/*"):
        self.lock = threading.Lock()
        self.heard: list[Heard] = []
        self.bad: list[tuple[str, bytes]] = []
        self.subs = [s.declare_subscriber(f"{key}/{k}", self._on) for k in ("state", "status")]

    def _on(self, sample) -> None:
        key, data = str(sample.key_expr), sample.payload.to_bytes()
        try:
            msg = decode(data, key.rsplit("/", 1)[-1])
        except ValueError:
            with self.lock:
                self.bad.append((key, data))
            return
        with self.lock:
            self.heard.append(Heard(time.monotonic(), key, msg))

    def of(self, kind: str, vehicle: str | None = None) -> list[Heard]:
        with self.lock:
            return [h for h in self.heard if h.key.endswith("/" + kind)
                    and (vehicle is None or h.msg["vehicle_id"] == vehicle)]

    def statuses(self, vehicle: str | None = None) -> list[str]:
        return [h.msg["kind"] for h in self.of("status", vehicle)]

    def wait(self, predicate, timeout: float, what: str = "condition") -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return
            time.sleep(0.02)
        raise AssertionError(f"{what} not met within {timeout} s; statuses {self.statuses()}")


class Proc:
    """``python -m companion ARGS`` (stdout/stderr to files) for a ``with`` block; stopped on
    exit whatever happened: SIGTERM first (a demo then stops the plant it started, which a
    SIGKILL would leave running), SIGKILL after 3 s."""

    def __init__(self, *args: str, tmp: Path, name: str):
        self.argv = [sys.executable, "-m", "companion", *with_log_dir(args, tmp / "logs")]
        self.out_path, self.err_path = tmp / f"{name}.out", tmp / f"{name}.err"
        self.proc: subprocess.Popen | None = None

    def __enter__(self) -> Proc:
        self._out, self._err = open(self.out_path, "w"), open(self.err_path, "w")
        self.proc = subprocess.Popen(self.argv, stdout=self._out, stderr=self._err, cwd=ROOT,
                                     env={**os.environ, "PYTHONUNBUFFERED": "1"})
        return self

    def __exit__(self, *exc) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(3.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._out.close()
        self._err.close()

    @property
    def stdout(self) -> str:
        return self.out_path.read_text()

    @property
    def stderr(self) -> str:
        return self.err_path.read_text()

    def wait(self, timeout: float) -> int:
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"{self.argv[3]} still running after {timeout} s; stderr:\n"
                                 f"{self.stderr[-2000:]}") from None

    def stop(self, sig: int = signal.SIGTERM, within: float = 2.0) -> tuple[int, float]:
        """Send ``sig``; the exit code and how long the process took to exit (it must within
        ``within`` s, else AssertionError)."""
        t0 = time.monotonic()
        self.proc.send_signal(sig)
        try:
            code = self.proc.wait(within)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"{' '.join(self.argv[2:5])} did not exit within {within} s of "
                                 f"{signal.Signals(sig).name}; stderr:\n{self.stderr[-2000:]}"
                                 ) from None
        return code, time.monotonic() - t0

    def wait_line(self, text: str, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.stderr:
                return
            if self.proc.poll() is not None:
                break
            time.sleep(0.02)
        raise AssertionError(f"no {text!r} on stderr within {timeout} s:\n{self.stderr[-2000:]}")

    def result(self) -> dict[str, Any]:
        lines = [line for line in self.stdout.splitlines() if line.startswith("{")]
        assert lines, f"no JSON on stdout:\n{self.stdout}\nstderr:\n{self.stderr[-2000:]}"
        return json.loads(lines[-1])


def secret_file(path: Path, secret: str = "correct horse battery staple") -> Path:
    path.write_text(secret + "\n")
    path.chmod(0o600)
    return path


# --------------------------------------------------------------------------- fleets

@dataclass
class FleetRun:
    n: int
    snapshot: dict[str, Any]           # the monitor's --once --json snapshot
    results: list[dict[str, Any]]      # each companion's --json result (None: no result)
    codes: list[int | None]
    gaps_ms: dict[str, float]          # per vehicle: longest gap between state messages (record)
    counts: dict[str, int]
    wall_s: float
    exit_s: dict[str, float]           # monitor / router: seconds from SIGTERM to exit
    cpu_s: dict[str, float] = dataclasses.field(default_factory=dict)   # monitor / router CPU


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds a running process has used so far (Linux /proc; else NaN)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return math.nan
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _popen(argv: list[str], log: Path) -> subprocess.Popen:
    f = open(log, "w")
    try:
        return subprocess.Popen(argv, stdout=f, stderr=subprocess.STDOUT, cwd=ROOT,
                                env={**os.environ, "PYTHONUNBUFFERED": "1"})
    finally:
        f.close()


def run_fleet(n: int, tmp: Path, rate: float = 20.0, duration: float = 10.0,
              arm_delay: float | None = None, timeout: float = 120.0,
              tls: bool = False) -> FleetRun:
    """One router, ``n`` sitl-plant + ``companion run`` pairs in real time at ``rate`` Hz, all
    publishing through the router (client mode), and one ``companion monitor --once --json
    --record``. Plants refuse arming for ``arm_delay`` s so every pair starts tracking after all
    the processes are up. ``tls``: every link mutual TLS, each process with its own certificate
    (router, mon, rover1..n) and the access control of its role. Every process is killed on the
    way out, whatever happened."""
    from sitl_plant.testing import free_udp_port
    t0 = time.monotonic()
    arm_delay = arm_delay if arm_delay is not None else 4.0 + 0.5 * n
    mission = mission_file(tmp / "fleet.toml", duration)
    router_port = free_tcp_port()
    router_ep = tls_endpoint(router_port) if tls else endpoint(router_port)
    record = tmp / "fleet.jsonl"
    if tls:
        pki_dir = make_pki(tmp / "pki", {"router": "router", "mon": "monitor",
                                         **{f"rover{i}": "rover" for i in range(1, n + 1)}})
        isolated = ["--zenoh-config", str(tls_isolated(tmp))]

        def who(name: str) -> list[str]:
            return ["--zenoh-tls", str(pki_dir / name), *isolated]
    else:
        def who(name: str) -> list[str]:
            return list(ISOLATED)
    zenoh_client = ["--zenoh-mode", "client", "--zenoh-connect", router_ep]
    procs: list[subprocess.Popen] = []
    companions: list[subprocess.Popen] = []
    try:
        router = _popen([sys.executable, "-m", "companion", "router", "--zenoh-listen",
                         router_ep, *who("router")], tmp / "router.log")
        procs.append(router)
        deadline = time.monotonic() + 15.0
        while "routing" not in (tmp / "router.log").read_text():
            assert router.poll() is None and time.monotonic() < deadline, \
                (tmp / "router.log").read_text()
            time.sleep(0.05)
        monitor = _popen([sys.executable, "-m", "companion", "monitor", "--once", "--json",
                          "--wait", str(timeout), "--record", str(record), *zenoh_client,
                          *who("mon")], tmp / "monitor.out")
        procs.append(monitor)
        loop_rate = max(50.0, rate / 0.8 + 1)
        for i in range(1, n + 1):
            port = free_udp_port()
            procs.append(_popen(
                [sys.executable, "-m", "sitl_plant", "--connect", f"udpout:127.0.0.1:{port}",
                 "--sysid", str(i), "--d-cen", "0.3", "--arm-delay", str(arm_delay),
                 "--loop-rate", f"{loop_rate:g}", "--physics-dt", "0.002"],
                tmp / f"plant{i}.log"))
            c = _popen([sys.executable, "-m", "companion", "run", "--connect",
                        f"udpin:127.0.0.1:{port}", "--sysid", str(i), "--mission", str(mission),
                        "--arm", "--arm-timeout", "120", "--json", "-q", "--rate", f"{rate:g}",
                        "--log-dir", str(tmp / "logs"), *zenoh_client, *who(f"rover{i}")],
                       tmp / f"companion{i}.out")
            procs.append(c)
            companions.append(c)
        deadline = t0 + timeout
        for c in companions:
            c.wait(max(0.1, deadline - time.monotonic()))
        exit_s, cpu_s = {}, {}
        for name, p in (("monitor", monitor), ("router", router)):
            cpu_s[name] = cpu_seconds(p.pid)
            # --once: SIGTERM ends the monitor's wait and it prints the snapshot.
            t_sig = time.monotonic()
            p.send_signal(signal.SIGTERM)
            try:
                p.wait(5.0)
            except subprocess.TimeoutExpired:
                pass
            exit_s[name] = time.monotonic() - t_sig if p.poll() is not None else math.inf
        out = (tmp / "monitor.out").read_text()
        snap = json.loads([line for line in out.splitlines() if line.startswith("{")][-1])
        results, codes = [], []
        for i, c in enumerate(companions, 1):
            lines = [line for line in (tmp / f"companion{i}.out").read_text().splitlines()
                     if line.startswith("{")]
            results.append(json.loads(lines[-1]) if lines else None)
            codes.append(c.returncode)
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(3.0)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
    gaps: dict[str, float] = {}
    counts: dict[str, int] = {}
    last: dict[str, float] = {}
    for line in record.read_text().splitlines():
        r = json.loads(line)
        if not r["key"].endswith("/state"):
            continue
        vid = r["payload"]["vehicle_id"]
        counts[vid] = counts.get(vid, 0) + 1
        if vid in last:
            gaps[vid] = max(gaps.get(vid, 0.0), (r["rx"] - last[vid]) * 1e3)
        last[vid] = r["rx"]
    return FleetRun(n, snap, results, codes, gaps, counts, time.monotonic() - t0, exit_s, cpu_s)
