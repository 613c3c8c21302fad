"""``companion demo``: the README's first command, end to end (plant + companion processes)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from companion_harness import ROOT

FIELDS = ("f_cost", "steady_rms", "setpoints_sent", "telemetry_received", "loop_rate_hz",
          "latency_p50_ms", "latency_p99_ms", "duration_s", "plot")


def demo(*args: str, timeout: float = 120.0) -> tuple[subprocess.CompletedProcess, float]:
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, "-m", "companion", "demo", "--json", *args],
                       capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    return p, time.monotonic() - t0


def _plant_gone(result: dict) -> bool:
    """No process is left with the plant's command line (the demo killed what it started)."""
    needle = result["plant"].split("--connect ")[1].split()[0]
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            if needle in cmdline.read_bytes().replace(b"\0", b" ").decode(errors="replace"):
                return False
        except OSError:
            continue
    return True


def test_demo_defaults_json(tmp_path):
    p, wall = demo("--out", str(tmp_path))
    assert p.returncode == 0, p.stderr
    assert wall < 90.0
    lines = p.stdout.strip().splitlines()
    assert len(lines) == 1, "stdout must be exactly one JSON object"
    r = json.loads(lines[0])
    assert all(r.get(k) is not None for k in FIELDS), r
    assert r["reason"] == "mission_done" and r["duration_s"] >= 60.0 - 1e-6
    assert r["loop_rate_hz"] > 39.0 and r["setpoints_sent"] >= 2400
    assert r["steady_rms"] <= 0.3
    assert Path(r["plot"]).stat().st_size > 10_000
    assert _plant_gone(r)


def test_demo_paced_at_a_speedup(tmp_path):
    p, _ = demo("--out", str(tmp_path), "--speedup", "8", "--duration", "16", "--no-plot")
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    assert "--lockstep" not in r["plant"] and "--speedup 8.0" in r["plant"]
    assert r["duration_s"] >= 16.0 - 1e-6 and "plot" not in r
    assert r["steady_rms"] <= 0.3
    assert _plant_gone(r)
