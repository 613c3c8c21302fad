"""The companion as an OS process: ``python -m companion ...`` run to its end
(:func:`companion_cli`, :func:`companion_json`) or held for a ``with`` block (:class:`Companion`),
from the checkout (:data:`ROOT`), its flight logs kept out of the checkout's ``logs/``.
"""

from __future__ import annotations

import atexit
import json
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]     # the checkout: missions/, benchmarks/
_LOGS: Path | None = None


# the commands that write flight logs, and the flags that say where (or that none is written)
_LOGGING = ("run", "demo", "identify", "calibrate")
_LOG_SAID = ("--log-dir", "--no-log", "--config", "--help", "-h", "--print-config")


def scratch_log_dir() -> Path:
    """A folder for the flight logs of runs whose test did not name one (never the checkout's
    ``logs/``), one per test process, removed when it exits (after every test has read them)."""
    global _LOGS
    if _LOGS is None:
        _LOGS = Path(tempfile.mkdtemp(prefix="pzc-test-logs-"))
        atexit.register(shutil.rmtree, _LOGS, True)
    return _LOGS


def with_log_dir(args: Sequence[str], folder: Path | None = None) -> list[str]:
    """``companion`` arguments with ``--log-dir`` added (``folder``, else the scratch folder)
    when the command writes flight logs and the test said nothing of where (a config file
    may say it; the default, ./logs, is the checkout's when run from it)."""
    args = list(args)
    if args[:1] and args[0] in _LOGGING and not any(a in _LOG_SAID for a in args):
        args += ["--log-dir", str(folder or scratch_log_dir())]
    return args


def companion_cli(*args: str, timeout: float, cwd: Path = ROOT, env: dict[str, str] | None = None,
                  prefix: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    """``python -m companion ARGS`` run to its end, output captured. ``timeout`` is each test
    file's guard against a hung run (it fails the test), not a speed target. Run from the
    checkout, its flight logs go to the scratch folder unless the test says where."""
    argv = with_log_dir(args) if Path(cwd) == ROOT else list(args)
    return subprocess.run([*prefix, sys.executable, "-m", "companion", *argv], capture_output=True,
                          text=True, timeout=timeout, cwd=cwd, env=env)


class Companion:
    """``python -m companion run --connect udpin:127.0.0.1:PORT ARGS`` (or ``url=``) for a
    ``with`` block; killed on exit if still running.

    Two threads drain its stdout and stderr as it writes them, so a chatty run never blocks on
    a full pipe while the test waits on something else, and a failed wait can say what the run
    said so far (``said()``)."""

    def __init__(self, port: int | None, *args: str, command: str = "run",
                 url: str | None = None):
        self.argv = [sys.executable, "-m", "companion", *with_log_dir(
            [command, "--connect", url or f"udpin:127.0.0.1:{port}", *args])]
        self.proc: subprocess.Popen | None = None
        self.stdout = self.stderr = ""
        self._out: list[str] = []
        self._err: list[str] = []
        self._drains: list[threading.Thread] = []
        self.started_at = 0.0

    def __enter__(self) -> Companion:
        self.proc = subprocess.Popen(self.argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, cwd=ROOT)
        self.started_at = time.monotonic()
        self._drains = [threading.Thread(target=_drain, args=(pipe, into), daemon=True)
                        for pipe, into in ((self.proc.stdout, self._out),
                                           (self.proc.stderr, self._err))]
        for t in self._drains:
            t.start()
        return self

    def __exit__(self, *exc) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self._collect()

    def said(self) -> str:
        """What the run has written to stderr so far."""
        return "".join(self._err)

    def _collect(self) -> None:
        for t in self._drains:
            t.join(5.0)
        self.stdout, self.stderr = "".join(self._out), "".join(self._err)

    def wait_for_stderr(self, needle: str, timeout: float) -> None:
        """Wait until the run has said ``needle`` on stderr (what the run says, not a guess at
        how long it takes on a loaded machine)."""
        self.wait_until(lambda: needle in self.said(), timeout, f"{needle!r} said")

    def wait_until(self, predicate, timeout: float, what: str = "condition") -> None:
        """Wait for ``predicate()`` while the run is alive; if it ends or ``timeout`` passes
        first, fail with its exit code and what it said."""
        deadline = time.monotonic() + timeout
        while not predicate():
            code = self.proc.poll()
            if code is not None or time.monotonic() > deadline:
                if code is not None:
                    self._collect()
                raise AssertionError(f"{what}: not met within {timeout} s (companion "
                                     f"{'exited ' + str(code) if code is not None else 'running'})"
                                     f":\n{self.said()}")
            time.sleep(0.02)

    def wait_bound(self, port: int, timeout: float = 60.0) -> None:
        """Wait until the run has bound its ``udpin`` port (read from /proc/net/udp, so the
        check never takes the port from it). A plant started after this boots into a companion
        already listening, however long the companion took to import on a loaded machine."""
        local = f":{port:04X}"   # local_address, the second column: 0100007F:PORT in hex

        def bound() -> bool:
            with open("/proc/net/udp") as table:
                return any(line.split()[1].endswith(local) for line in list(table)[1:])
        self.wait_until(bound, timeout, f"udp port {port} bound")

    def wait(self, timeout: float) -> int:
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            self._collect()
            raise AssertionError(f"companion still running after {timeout} s:\n"
                                 f"{self.stderr}") from None
        self._collect()
        return self.proc.returncode

    def result(self) -> dict[str, Any]:
        lines = [line for line in self.stdout.splitlines() if line.startswith("{")]
        assert lines, f"no JSON result; stdout:\n{self.stdout}\nstderr:\n{self.stderr}"
        return json.loads(lines[-1])


def _drain(pipe, into: list[str]) -> None:
    for line in pipe:
        into.append(line)
    pipe.close()


def companion_json(argv: list[str], timeout: float) -> dict:
    """``companion ARGV`` as a process, from the checkout; its JSON result (the last stdout
    line), or exit with the tail of its stderr (a benchmark's way: it has no test to fail)."""
    p = subprocess.run([sys.executable, "-m", "companion", *argv], capture_output=True,
                       text=True, timeout=timeout, cwd=ROOT)
    if p.returncode != 0:
        raise SystemExit(f"companion {argv[0]}: exit {p.returncode}: {p.stderr.strip()[-600:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])
