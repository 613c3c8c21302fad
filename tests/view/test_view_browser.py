"""``companion view`` in a real browser: a demo (the companion flying sitl-plant) publishes on
Zenoh, the view subscribes and serves Rerun's web viewer, headless Chromium (Debian's package,
driven by playwright) opens it with every request off this machine refused, and the test reads
the screenshots' pixels: the rover (green: tracking) and its path are drawn on the map and move;
after the demo is killed the rover turns grey (stale). Skips, saying why, without a browser.

Chromium draws the viewer with its software rasteriser (SwiftShader), as many frames as it can:
about 1.5 cores on a quiet 2-core machine, and ~10 s of CPU to load the viewer and draw its
first frame. So the page is 640x400 (a frame costs about half of 900x540's), the screenshots
come a second apart and each phase has its own deadline; the test prints how long each took."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from testbed.process import ROOT
from testbed.zenoh_fleet import free_tcp_port

pytest.importorskip("rerun", reason="companion view needs rerun-sdk (pip install .[view])")
playwright = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
Image = pytest.importorskip("PIL.Image")


def _chromium() -> str | None:
    for name in (os.environ.get("CHROMIUM"), "chromium", "chromium-browser", "google-chrome"):
        if name and (path := shutil.which(name)):
            return path
    return None


CHROMIUM = _chromium()
# solo: Chromium's software rasteriser takes ~1.5 cores while it runs; beside the parallel run
# it starves the real-time tests (make test runs it alone, after them)
pytestmark = [pytest.mark.solo, pytest.mark.timeout(420), pytest.mark.skipif(
    CHROMIUM is None, reason="no Chromium installed (apt-get install chromium; .ci/run does)")]

# playwright adds its own switches (headless, a fresh profile, no background networking, no
# component updates, no renderer backgrounding, SwiftShader for WebGL); these are ours
CHROMIUM_ARGS = ["--no-sandbox", "--disable-quic"]
VIEWPORT = {"width": 640, "height": 400}
OFFSITE = re.compile(r"^(?!http://127\.0\.0\.1[:/])")     # any URL but this machine's
PATH_COLOUR = (0, 190, 255)      # the first rover's driven path (companion/view/draw.py PATHS)
TRACKING = (40, 200, 90)
STALE = (128, 128, 128)
SHOTS = os.environ.get("PZC_VIEW_SCREENSHOT")   # where to keep the live view's screenshot
# Seconds each phase may take. Generous: the first one compiles the viewer (~50 MB of wasm),
# which takes a quiet machine ~5 s and a loaded one several times that.
FIRST_DRAWN, MOVING, STALE_SHOWN = 180.0, 60.0, 60.0


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


def _map(png: Path) -> dict[tuple[int, int, int], list[tuple[int, int]]]:
    """(x, y) of the map panel's pixels near each colour: its left 58 %, between the panel's
    title bar (60 px) and the time panel (the last 32 px)."""
    img = Image.open(png).convert("RGB")
    w, h = img.size
    data = img.load()
    found: dict[tuple[int, int, int], list[tuple[int, int]]] = {
        PATH_COLOUR: [], TRACKING: [], STALE: []}
    tols = {PATH_COLOUR: 28, TRACKING: 28, STALE: 10}
    for y in range(60, h - 32):
        for x in range(int(w * 0.58)):
            r, g, b = data[x, y]
            for colour, pts in found.items():
                tol = tols[colour]
                if abs(r - colour[0]) <= tol and abs(g - colour[1]) <= tol \
                        and abs(b - colour[2]) <= tol:
                    pts.append((x, y))
    return found


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
    phases: dict[str, float] = {}
    t0 = time.monotonic()
    shots = 0

    def shoot(name: str, deadline: float) -> dict[tuple[int, int, int], list[tuple[int, int]]]:
        nonlocal shots
        shots += 1
        # a screenshot waits for the viewer's next frame
        page.screenshot(path=tmp_path / name,
                        timeout=1000 * max(10.0, deadline - time.monotonic()))
        return _map(tmp_path / name)

    try:
        url = json.loads(_first_line(view, 90.0))["url"]
        assert url.startswith(f"http://127.0.0.1:{web}/")
        with playwright.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport=VIEWPORT)
            # No internet: whatever the page asks of another host is refused (and listed). A
            # pattern, not a Python predicate: playwright then pauses only those requests, where
            # a predicate holds every request (the wasm, the stream) until this thread next
            # calls playwright.
            page.route(OFFSITE,
                       lambda route: (offsite.append(route.request.url), route.abort()))
            page.goto(url)
            # The rover flies while the viewer loads; the view's server hands a late viewer
            # the newest data first.
            demo = _spawn("demo", "--speedup", "1", "--duration", "300", "--no-plot",
                          "--no-log", "--zenoh-connect", ep, "--no-zenoh-scouting", "-q")
            phases["page"] = time.monotonic() - t0
            # 1. the rover (green) and its path (blue) drawn
            first = None
            deadline = time.monotonic() + FIRST_DRAWN
            while first is None and time.monotonic() < deadline:
                time.sleep(1.0)
                seen = shoot("first.png", deadline)
                if len(seen[PATH_COLOUR]) > 100 and len(seen[TRACKING]) > 20:
                    first = (seen, time.monotonic())
            assert first is not None, (
                f"the map never showed the rover and its path within {FIRST_DRAWN:.0f} s "
                f"(last screenshot: {len(seen[PATH_COLOUR])} path pixels, "
                f"{len(seen[TRACKING])} tracking-green)")
            phases["drawn"] = time.monotonic() - t0
            if SHOTS:
                shutil.copy(tmp_path / "first.png", SHOTS)
            # 2. both move: the rover's centre shifts, the path's pixels change
            moved = False
            deadline = time.monotonic() + MOVING
            while not moved and time.monotonic() < deadline:
                time.sleep(1.0)
                seen = shoot("live.png", deadline)
                rover = seen[TRACKING]
                if len(rover) <= 20 or time.monotonic() - first[1] < 2.0:
                    continue
                (x0, y0), (x1, y1) = _centre(first[0][TRACKING]), _centre(rover)
                moved = abs(x1 - x0) + abs(y1 - y0) > 8.0 and \
                    set(seen[PATH_COLOUR]) != set(first[0][PATH_COLOUR])
            assert moved, f"the rover and its path were drawn but not seen moving in {MOVING:.0f} s"
            assert len(seen[STALE]) < 20, "a rover drawn grey while it was still publishing"
            phases["moving"] = time.monotonic() - t0
            # 3. silence: the rover (and its plant) killed, the view draws it grey
            assert demo.poll() is None, "the demo ended before the view was checked"
            os.killpg(demo.pid, signal.SIGKILL)
            demo.wait(10)
            killed = time.monotonic()
            stale = False
            deadline = killed + STALE_SHOWN
            while not stale and time.monotonic() < deadline:
                time.sleep(1.0)
                seen = shoot("stale.png", deadline)
                stale = len(seen[STALE]) > 20 and len(seen[TRACKING]) <= 4
            assert stale, (f"the silent rover was not drawn stale (grey) within "
                           f"{STALE_SHOWN:.0f} s: {len(seen[STALE])} grey pixels, "
                           f"{len(seen[TRACKING])} tracking-green")
            phases["stale"] = time.monotonic() - t0
            phases["kill_to_grey"] = time.monotonic() - killed
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
        print("\nbrowser test phases (s from the view's start): "
              + ", ".join(f"{k} {v:.1f}" for k, v in phases.items()) + f"; {shots} screenshots, {len(offsite)} requests off this machine refused")
    out, err = outputs[view.pid]
    assert view.returncode == 0, err
    summary = json.loads(out.strip().splitlines()[-1])      # the view's own account
    assert summary["rovers"]["rover1"]["state_msgs"] > 100
    print(f"view with a browser open: {summary['frames']} frames, {summary['cpu_s']:.1f} s CPU "
          f"over {summary['wall_s']:.1f} s")
    # Everything the viewer needs came from this machine: only extras were refused.
    assert all(("fonts.g" in u) or ("rerun.io" in u) or ("github.com" in u) for u in offsite), \
        offsite
