"""Helpers for tests with real Zenoh sessions on loopback: isolated configs (multicast scouting
off, explicit endpoints, free ports), a subscriber that keeps what it hears, and process helpers
that always stop what they start."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import zenoh

from companion.bus import decode

ROOT = Path(__file__).resolve().parents[1]
ISOLATED = ["--no-zenoh-scouting"]


def free_tcp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def endpoint(port: int) -> str:
    return f"tcp/127.0.0.1:{port}"


def config(mode: str = "peer", listen: list[str] | None = None,
           connect: list[str] | None = None) -> zenoh.Config:
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(mode))
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("listen/endpoints", json.dumps(listen or []))
    c.insert_json5("connect/endpoints", json.dumps(connect or []))
    return c


@contextlib.contextmanager
def session(**kwargs) -> Iterator[zenoh.Session]:
    """A session that is closed on every path out (callbacks would otherwise hang the exit)."""
    s = zenoh.open(config(**kwargs))
    try:
        yield s
    finally:
        s.close()


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
    """``python -m companion ARGS`` (stdout/stderr to files) for a ``with`` block; killed on
    exit whatever happened."""

    def __init__(self, *args: str, tmp: Path, name: str):
        self.argv = [sys.executable, "-m", "companion", *args]
        self.out_path, self.err_path = tmp / f"{name}.out", tmp / f"{name}.err"
        self.proc: subprocess.Popen | None = None

    def __enter__(self) -> "Proc":
        self._out, self._err = open(self.out_path, "w"), open(self.err_path, "w")
        self.proc = subprocess.Popen(self.argv, stdout=self._out, stderr=self._err, cwd=ROOT,
                                     env={**os.environ, "PYTHONUNBUFFERED": "1"})
        return self

    def __exit__(self, *exc) -> None:
        if self.proc is not None and self.proc.poll() is None:
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


def mission_file(path: Path, duration: float, name: str = "ellipse") -> Path:
    path.write_text(f'name = "{name}"\nframe = "start"\nduration = {duration}\n'
                    '[trajectory]\nkind = "ellipse"\nf_r = 0.12\n')
    return path


def secret_file(path: Path, secret: str = "correct horse battery staple") -> Path:
    path.write_text(secret + "\n")
    path.chmod(0o600)
    return path
