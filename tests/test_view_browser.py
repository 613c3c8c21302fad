"""``companion view`` in a real browser: a demo (the companion flying sitl-plant) publishes on
Zenoh, the view subscribes and serves Rerun's web viewer, headless Chromium (Debian's package,
driven by playwright) opens it with every request off this machine refused, and the test reads
the screenshots' pixels: the rover (green: tracking) and its path are drawn on the map and move;
after the demo is killed the rover turns grey (stale). Skips, saying why, without a browser."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from companion_harness import ROOT
from zenoh_harness import free_tcp_port

pytest.importorskip("rerun", reason="companion view needs rerun-sdk (pip install .[view])")
playwright = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
Image = pytest.importorskip("PIL.Image")


def _chromium() -> str | None:
    for name in (os.environ.get("CHROMIUM"), "chromium", "chromium-browser", "google-chrome"):
        if name and (path := shutil.which(name)):
            return path
    return None


CHROMIUM = _chromium()
pytestmark = [pytest.mark.timeout(1200), pytest.mark.skipif(
    not os.environ.get("PZC_BROWSER_TEST"),
    reason="candidate: headless Chromium's software renderer falls minutes behind the stream "
           "under load (it passed 2 of 5 runs on 2026-12-02): PZC_BROWSER_TEST=1 runs it"),
    pytest.mark.skipif(
    CHROMIUM is None, reason="no Chromium installed (apt-get install chromium; .ci/run does)")]

PATH_COLOUR = (0, 190, 255)      # the first rover's driven path (companion/view/draw.py PATHS)
TRACKING = (40, 200, 90)
STALE = (128, 128, 128)
SHOTS = os.environ.get("PZC_VIEW_SCREENSHOT")   # where to keep the live view's screenshot


def _spawn(*args: str) -> subprocess.Popen:
    # its own process group: the demo's plant goes down with it (SIGKILL leaves no orphan)
    return subprocess.Popen([sys.executable, "-m", "companion", *args], cwd=ROOT, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)


def _first_line(proc: subprocess.Popen, timeout: float) -> str:
    box: list[str] = []
    reader = threading.Thread(target=lambda: box.append(proc.stdout.readline()), daemon=True)
    reader.start()
    reader.join(timeout)
    assert box and box[0], f"no URL from companion view within {timeout} s"
    return box[0]


def _pixels(png: Path, colour: tuple[int, int, int], tol: int = 28) -> list[tuple[int, int]]:
    """(x, y) of the map panel's pixels within ``tol`` of ``colour`` (left 58 %, below the bar)."""
    img = Image.open(png).convert("RGB")
    w, h = img.size
    data = img.load()
    out = []
    for y in range(60, h - 50, 2):
        for x in range(0, int(w * 0.58), 2):
            r, g, b = data[x, y]
            if abs(r - colour[0]) <= tol and abs(g - colour[1]) <= tol and abs(b - colour[2]) <= tol:
                out.append((x, y))
    return out


def _centre(points: list[tuple[int, int]]) -> tuple[float, float]:
    return (sum(p[0] for p in points) / len(points), sum(p[1] for p in points) / len(points))


def test_the_view_draws_the_rover_and_its_path_and_they_move(tmp_path):
    zport, web, grpc = free_tcp_port(), free_tcp_port(), free_tcp_port()
    ep = f"tcp/127.0.0.1:{zport}"
    view = _spawn("view", "--zenoh-listen", ep, "--no-zenoh-scouting", "--web-port", str(web),
                  "--grpc-port", str(grpc), "--stale-after", "2", "--refresh", "0.25", "--json")
    offsite: list[str] = []
    demo: subprocess.Popen | None = None
    outputs: dict[int, tuple[str, str]] = {}
    try:
        url = json.loads(_first_line(view, 90.0))["url"]
        assert url.startswith(f"http://127.0.0.1:{web}/")
        with playwright.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
            page = browser.new_page(viewport={"width": 900, "height": 540})
            # No internet: whatever the page asks of another host is refused (and listed).
            page.route(lambda u: not u.startswith("http://127.0.0.1"),
                       lambda route: (offsite.append(route.request.url), route.abort()))
            page.goto(url)
            # The viewer (~50 MB of wasm) first loads and compiles: minutes on a busy machine
            # with a software rasteriser. The rover starts once the page is up, so the viewer
            # is not handed minutes of backlog at once.
            page.wait_for_function(
                "() => { const e = document.getElementById('center_text');"
                " return e !== null && !e.classList.contains('visible'); }", timeout=400_000)
            demo = _spawn("demo", "--speedup", "1", "--duration", "400", "--no-plot",
                          "--no-log", "--zenoh-connect", ep, "--no-zenoh-scouting", "-q")
            first = None
            deadline = time.monotonic() + 240.0
            while time.monotonic() < deadline:          # the software rasteriser is slow
                time.sleep(3.0)
                shot = tmp_path / "live.png"
                page.screenshot(path=shot, timeout=240_000)
                path, rover = _pixels(shot, PATH_COLOUR), _pixels(shot, TRACKING)
                if first is None:
                    if len(path) > 40 and len(rover) > 10:
                        first = (path, rover, time.monotonic())
                        if SHOTS:
                            shutil.copy(shot, SHOTS)
                    continue
                if time.monotonic() - first[2] < 8.0:
                    continue
                moved = abs(_centre(rover)[0] - _centre(first[1])[0]) + \
                    abs(_centre(rover)[1] - _centre(first[1])[1]) if rover else 0.0
                if moved > 4.0 and set(path) != set(first[0]):
                    break
            else:
                pytest.fail(f"the map never showed the rover and its path moving "
                            f"(first seen: {first is not None}); last screenshot {shot}")
            assert demo.poll() is None, "the demo ended before the view was checked"
            os.killpg(demo.pid, signal.SIGKILL)        # the rover (and its plant) go silent
            demo.wait(10)
            deadline = time.monotonic() + 240.0       # the viewer may lag the stream
            while time.monotonic() < deadline:
                time.sleep(3.0)
                page.screenshot(path=tmp_path / "stale.png", timeout=240_000)
                grey, green = _pixels(tmp_path / "stale.png", STALE, 10), \
                    _pixels(tmp_path / "stale.png", TRACKING)
                if len(grey) > 10 and len(green) <= 2:
                    break
            else:
                pytest.fail("the silent rover was never drawn stale (grey)")
            browser.close()
    finally:
        procs = [p for p in (demo, view) if p is not None]
        for proc in procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        if demo is not None:
            try:
                os.killpg(demo.pid, signal.SIGTERM)     # the demo's plant, whatever happened
            except ProcessLookupError:
                pass
        for proc in procs:
            try:
                outputs[proc.pid] = proc.communicate(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                outputs[proc.pid] = proc.communicate()
    out, err = outputs[view.pid]
    assert view.returncode == 0, err
    summary = json.loads(out.strip().splitlines()[-1])      # the view's own account
    assert summary["rovers"]["rover1"]["state_msgs"] > 100
    print(f"\nview with a browser open: {summary['frames']} frames, {summary['cpu_s']:.1f} s CPU "
          f"over {summary['wall_s']:.1f} s")
    # Everything the viewer needs came from this machine: only extras were refused.
    assert all(("fonts.g" in u) or ("rerun.io" in u) or ("github.com" in u) for u in offsite), \
        offsite
