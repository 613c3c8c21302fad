"""What ``companion view`` costs: its own CPU, and the rover's publish rate with and without it.

A demo (the companion flying sitl-plant at real time) publishes on Zenoh; ``companion monitor
--once --json`` counts the state samples that reach a subscriber over WINDOW seconds, first with
no view, then with ``companion view`` subscribed (its CPU from its own getrusage summary).
With ``--browser``, headless Chromium (playwright, a 640x400 page, as
tests/view/test_view_browser.py) has the view open during the second window, and its CPU (every
Chromium process, from /proc) is printed too: a browser drawing with its software rasteriser
is the worst case, a GPU browser costs far less.
Loopback only, multicast scouting off. Run: ``python benchmarks/bench_view.py [--browser]``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

WINDOW = 20.0
LOAD = 15.0          # s for the browser to load the viewer (~10 s of CPU) before the window


def port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def companion(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "companion", *args], text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)


def rate(ep: str) -> float:
    p = companion("monitor", "--zenoh-connect", ep, "--no-zenoh-scouting", "--once", "--json",
                  "--wait", str(WINDOW))
    out, _ = p.communicate(timeout=WINDOW + 60)
    v = json.loads(out.strip().splitlines()[-1])["vehicles"]
    return v[0]["state_msgs"] / WINDOW if v else 0.0


def chromium_cpu() -> float:
    """CPU seconds of every running Chromium process (this benchmark's only, on a quiet box)."""
    total = 0
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError):
            text = stat.read_text()
            if "chrom" in text[text.find("("):text.rfind(")")]:
                fields = text.rsplit(")", 1)[1].split()
                total += int(fields[11]) + int(fields[12])
    return total / os.sysconf("SC_CLK_TCK")


@contextlib.contextmanager
def browser(url: str | None) -> Iterator[None]:
    if url is None:
        yield
        return
    from playwright.sync_api import sync_playwright
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=exe, args=["--no-sandbox", "--disable-quic"])
        page = b.new_page(viewport={"width": 640, "height": 400})
        # a pattern (only those requests wait for this thread), offline as the test
        page.route(re.compile(r"^(?!http://127\.0\.0\.1[:/])"), lambda r: r.abort())
        page.goto(url)
        time.sleep(LOAD)                      # the viewer loaded and drawing before the window
        try:
            yield
        finally:
            b.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--browser", action="store_true", help="a headless Chromium has the view open")
    args = ap.parse_args()
    ep = f"tcp/127.0.0.1:{port()}"
    demo = companion("demo", "--speedup", "1", "--duration", "300", "--no-plot", "--no-log",
                     "--zenoh-listen", ep, "--no-zenoh-scouting", "-q")
    try:
        time.sleep(5)
        without = rate(ep)
        view = companion("view", "--zenoh-connect", ep, "--no-zenoh-scouting", "--web-port",
                         str(port()), "--grpc-port", str(port()), "--json")
        url = json.loads(view.stdout.readline())["url"]     # serving
        with browser(url if args.browser else None):
            c0, t0 = chromium_cpu(), time.monotonic()
            with_view = rate(ep)
            chromium = (chromium_cpu() - c0) / (time.monotonic() - t0)

        view.terminate()
        out, _ = view.communicate(timeout=60)
        summary = json.loads(out.strip().splitlines()[-1])
    finally:
        demo.terminate()
        demo.communicate(timeout=30)
    print(f"state samples/s reaching a subscriber: without the view {without:.1f}, "
          f"with it {with_view:.1f}")
    print(f"view: {summary['samples']} samples, {summary['frames']} frames, "
          f"{summary['cpu_s']:.2f} s CPU over {summary['wall_s']:.1f} s = "
          f"{100 * summary['cpu_s'] / summary['wall_s']:.1f} % of one core "
          + ("(a headless Chromium open)" if args.browser else "(no browser open)"))
    if args.browser:
        print(f"Chromium (software rasteriser, 640x400) while it was open: "
              f"{100 * chromium:.0f} % of one core")


if __name__ == "__main__":
    main()
