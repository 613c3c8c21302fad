"""``companion report``: a sitl-plant flight (a real demo, its logs and record) becomes one
self-contained HTML page: the paper's metrics as ``companion plot`` computes them, the figures
inline, the gains, the vehicle file and the command line; nothing fetched from elsewhere."""

from __future__ import annotations

import base64
import json
import re
from functools import partial
from pathlib import Path

import pytest

from testbed.process import ROOT, companion_cli

VEHICLE = ROOT / "companion" / "sim" / "vehicles" / "ardupilot_skid.toml"


companion = partial(companion_cli, timeout=180.0)


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    logs = tmp_path_factory.mktemp("logs")
    p = companion("demo", "--no-zenoh", "--json", "--no-plot", "--duration", "10", "--log-dir",
                  str(logs), "--vehicle", str(VEHICLE))
    assert p.returncode == 0, p.stderr
    return logs, json.loads(p.stdout.strip().splitlines()[-1])


def test_a_flight_becomes_one_self_contained_page(flown, tmp_path):
    logs, result = flown
    out = tmp_path / "report.html"
    p = companion("report", str(logs), "--out", str(out), "--json")
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["pages"] == [str(out)]
    page = out.read_text()
    # offline: no script, nothing loaded from a URL; the figures are inline PNGs that decode
    assert "<script" not in page and not re.search(r'(src|href)="(https?:)?//', page)
    images = re.findall(r'src="data:image/png;base64,([^"]+)"', page)
    assert len(images) == 4
    assert all(base64.b64decode(i)[:8] == b"\x89PNG\r\n\x1a\n" for i in images)
    plot = companion("plot", result["csv"], "--out", str(tmp_path / "fig"), "--json")
    m = json.loads(plot.stdout)
    assert f"{m['f_cost']:.4f}" in page and f"{m['steady_rms']:.4f}" in page
    assert f"{result['gains']['k_dc']:.6g}" in page and "k_dc" in page
    assert str(VEHICLE) in page and "pzc-rover/vehicle/1" in page      # the file and its text
    assert "demo --no-zenoh --json" in page                             # the command line
    assert "mission_done" in page


def test_several_flights_give_a_page_each_and_an_index(flown, tmp_path):
    logs, _ = flown
    second = tmp_path / "logs"
    second.mkdir()
    for f in logs.iterdir():
        (second / f.name).write_bytes(f.read_bytes())
        (second / ("b-" + f.name)).write_bytes(f.read_bytes())
    (second / ("b-" + next(logs.glob("*.json")).name)).unlink()      # a run with no record
    out = tmp_path / "r" / "report.html"
    p = companion("report", str(second), "--out", str(out), "--json")
    assert p.returncode == 0, p.stderr
    pages = json.loads(p.stdout)["pages"]
    assert len(pages) == 3 and pages[0] == str(out)
    index = out.read_text()
    assert all(Path(x).name in index for x in pages[1:])
    without = next(Path(x) for x in pages[1:] if "-b-" in Path(x).name)
    assert "No flight record" in without.read_text()


@pytest.mark.parametrize("args, expect", [
    (["/nonexistent/logs"], "no such file or folder"),
    ([str(ROOT / "docs")], "no flight log"),
    ([str(ROOT / "docs"), "--out", "x.pdf"], "must end in .html"),
])
def test_bad_input_is_a_one_line_error(args, expect):
    p = companion("report", *args)
    assert p.returncode == 2 and expect in p.stderr and "Traceback" not in p.stderr, p.stderr
