"""``companion demo``: the README's first command, end to end (plant + companion processes)."""

from __future__ import annotations

import json
import math
import subprocess
import time
from pathlib import Path

import pytest

from testbed.process import companion_cli

FIELDS = ("f_cost", "steady_rms", "setpoints_sent", "telemetry_received", "loop_rate_hz",
          "latency_p50_ms", "latency_p99_ms", "duration_s", "plot")


def demo(*args: str, timeout: float = 120.0) -> tuple[subprocess.CompletedProcess, float]:
    t0 = time.monotonic()
    p = companion_cli("demo", "--json", *args, timeout=timeout)
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


@pytest.mark.solo   # judged against the wall clock: alone, after the parallel run
def test_demo_paced_at_a_speedup(tmp_path):
    p, _ = demo("--out", str(tmp_path), "--speedup", "8", "--duration", "16", "--no-plot")
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    assert "--lockstep" not in r["plant"] and "--speedup 8.0" in r["plant"]
    assert r["duration_s"] >= 16.0 - 1e-6 and "plot" not in r
    assert r["steady_rms"] <= 0.3
    assert _plant_gone(r)


@pytest.mark.parametrize("controller", ["pid", "kanayama"])
def test_demo_flies_a_baseline_controller_as_simulate_predicts(tmp_path, controller):
    """``--controller`` reaches the live loop: the bundled plant (lockstep) tracks the paper's
    ellipse with the baseline, the result names it and its own default gains, and the steady
    error is the one ``companion simulate`` predicts for the same rover and reference."""
    p, _ = demo("--controller", controller, "--duration", "20", "--no-plot",
                "--log-dir", str(tmp_path / "logs"))
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    assert r["reason"] == "mission_done" and r["duration_s"] >= 20.0 - 1e-6
    assert r["controller"] == controller
    assert r["gains_source"].startswith(f"{controller} defaults (")
    assert math.isfinite(r["f_cost"]) and 0.0 < r["steady_rms"] < 2.0
    # the same reference, rover (the paper's, d_cen 0.3 as the demo's plant) and rate, simulated
    mission = tmp_path / "ellipse.toml"
    mission.write_text('name = "e"\nframe = "start"\nduration = 20.0\nrate_hz = 40.0\n'
                       '[trajectory]\nkind = "ellipse"\nf_r = 0.12\nax = 6.0\nbx = -1.0\n'
                       'ay = 2.0\nby = 3.0\n[vehicle]\nd_cen = 0.3\nw_c = 20.0\n')
    s = companion_cli("simulate", "--mission", str(mission),
                      "--controller", controller, "--json", timeout=60)
    predicted = json.loads(s.stdout)
    assert predicted["controller"] == controller and predicted["gains"] == r["gains_source"]
    assert r["steady_rms"] == pytest.approx(predicted["steady_rms"], rel=0.1)


def test_demo_text_output_names_the_controller(tmp_path):
    p = companion_cli("demo", "--controller", "kanayama",
                      "--duration", "5", "--no-plot", "--no-log", "-q", timeout=120)
    assert p.returncode == 0, p.stderr
    assert "controller  kanayama\n" in p.stdout
