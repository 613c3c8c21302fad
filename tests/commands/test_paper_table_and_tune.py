"""`companion paper-table` and `companion tune` as a user runs them: real processes, real files.

The three paper-table runs are the issue's acceptance figures (the paper's headline at 1 kHz,
the tuned gains at 40 Hz, and a slow rover at 40 Hz with w_c 1.2 rad/s).
"""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path

import pytest

from companion.sim import gains as gains_mod
from testbed.process import companion_cli

ROOT = Path(__file__).resolve().parents[2]


companion = partial(companion_cli, timeout=240)


def table(*args: str) -> dict:
    proc = companion("paper-table", "--json", "--no-progress", *args)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def _cells(d: dict, name: str, d_cen_zero_only: bool = False) -> list[dict]:
    return [s["controllers"][name] for s in d["scenarios"]
            if not d_cen_zero_only or s["d_cen"] == 0.0]


@pytest.mark.slow   # long: started first under workers (conftest.py)
def test_paper_table_at_1_khz_reproduces_the_paper():
    d = table()
    assert (d["rate_hz"], d["w_c"], d["duration_s"]) == (1000.0, 20.0, 60.0)
    assert [(s["f_r"], s["d_cen"]) for s in d["scenarios"]] == [
        (0.04, 0.0), (0.08, 0.0), (0.12, 0.0), (0.12, 0.0), (0.12, 0.3), (0.12, 0.6)]
    assert set(d["average"]) == {"pzc", "pzc_tuned", "pid", "kanayama"}
    # The paper's headline: PZC's average f_cost at least 37 % below PID's.
    assert d["improvement_vs_pid"] == pytest.approx(1 - d["average"]["pzc"] / d["average"]["pid"])
    assert d["improvement_vs_pid"] >= 0.37
    pzc = _cells(d, "pzc")
    assert max(c["steady_rms"] for c in pzc) <= 0.25
    costs = [c["f_cost"] for c in pzc]
    assert max(costs) / min(costs) <= 1.5            # "consistent performance"
    assert d["pzc_tuned_source"].startswith("shipped rate1000_wc20.toml")


def test_paper_table_at_40_hz_tuned_beats_pid():
    d = table("--rate", "40")
    assert d["rate_hz"] == 40.0
    assert d["improvement_vs_pid_tuned"] >= 0.37
    assert d["pzc_tuned_source"].startswith("shipped rate40_wc20.toml")


def test_paper_table_slow_rover_tuned_halves_pid():
    d = table("--rate", "40", "--w-c", "1.2")
    tuned = _cells(d, "pzc_tuned", d_cen_zero_only=True)
    pid = _cells(d, "pid", d_cen_zero_only=True)
    mean = lambda cells: sum(c["f_cost"] for c in cells) / len(cells)
    assert 1 - mean(tuned) / mean(pid) >= 0.50
    assert d["scenarios"][0]["f_r"] == 0.04 and tuned[0]["steady_rms"] <= 0.35
    assert not any(c["diverged"] for c in _cells(d, "pzc_tuned"))


def test_paper_table_plots_and_literal_law(tmp_path):
    out = tmp_path / "figs"
    d = table("--rate", "100", "--duration", "8", "--plot", str(out), "--literal", "--jobs", "1",
              "--gains", str(gains_mod.tuned_path(40, 20)))
    names = sorted(p.name for p in out.iterdir())
    assert names == ["fig04_paths.png", "fig05_x.png", "fig06_y.png", "fig07_speed.png",
                     "fig08_yaw_rate.png", "fig09_filter_errors.png", "fig10_paths_dcen.png",
                     "fig11_x_dcen.png", "fig12_y_dcen.png", "fig13_cost.png"]
    for name in names:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "pzc_literal" in d["average"] and len(d["plots"]) == 10


def test_paper_table_one_and_two_processes_agree():
    gains = str(gains_mod.tuned_path(40, 20))
    one = table("--rate", "50", "--duration", "6", "--jobs", "1", "--gains", gains)
    two = table("--rate", "50", "--duration", "6", "--jobs", "2", "--gains", gains)
    assert one["scenarios"] == two["scenarios"]


def test_table_without_gains_for_the_rate_tunes_on_the_spot():
    d = table("--rate", "10", "--duration", "4")
    assert d["pzc_tuned_source"].startswith("tuned on the fly")
    assert all(c["f_cost"] is not None for c in _cells(d, "pzc_tuned"))


def test_tune_writes_a_file_the_table_reads(tmp_path):
    out = tmp_path / "gains.toml"
    proc = companion("tune", "--rate", "20", "--population", "8", "--rounds", "1",
                     "--duration", "10", "--f-r", "0.04,0.12", "--out", str(out), "--json",
                     "--no-progress")
    assert proc.returncode == 0, proc.stderr
    d = json.loads(proc.stdout)
    assert d["rate_hz"] == 20.0 and d["evaluated"] == 8 and len(d["f_cost"]) == 2
    assert d["cost"] == pytest.approx(sum(d["f_cost"]) / 2, rel=1e-6)
    loaded = gains_mod.load(out)
    assert float(loaded.filter.k_df) == pytest.approx(d["filter"]["k_df"])
    t = table("--rate", "20", "--duration", "10", "--gains", str(out))
    assert t["pzc_tuned_source"] == f"file {out}"


def test_tune_prints_gains_in_text():
    proc = companion("tune", "--rate", "20", "--w-c", "2", "--population", "8", "--rounds", "1",
                     "--duration", "5", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert "k_df" in proc.stdout and "lambda_c" in proc.stdout and "cost (mean f_cost)" in proc.stdout


@pytest.mark.parametrize("command,args,text", [
    ("paper-table", ["--rate", "0"], "--rate"),
    ("paper-table", ["--w-c", "nan"], "--w-c"),
    ("paper-table", ["--gains", "missing.toml"], "missing.toml"),
    ("paper-table", ["--jobs", "0"], "--jobs"),
    ("tune", ["--rate", "-1"], "--rate"),
    ("tune", ["--rate", "40", "--f-r", "0.1,x"], "--f-r"),
    ("tune", ["--rate", "40", "--population", "2"], "--population"),
    ("tune", ["--rate", "40", "--out", "/nonexistent/dir/g.toml"], "--out"),
    ("tune", ["--rate", "40", "--d-cen", "-0.5"], "--d-cen"),
])
def test_bad_flags_are_one_line_errors(command, args, text):
    proc = companion(command, *args, timeout=60)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.count("\n") == 1 and text in proc.stderr, proc.stderr


def test_bad_gains_file_names_the_key(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[filter]\nk_df = 100.0\nlambda_f = -3\n[pzc]\nk_dc = 1.0\nlambda_c = 1.0\n")
    proc = companion("paper-table", "--gains", str(bad), "--duration", "1", timeout=60)
    assert proc.returncode == 2 and "lambda_f" in proc.stderr and str(bad) in proc.stderr
