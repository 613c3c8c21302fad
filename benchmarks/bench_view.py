"""What ``companion view`` costs: its own CPU, and the rover's publish rate with and without it.

A demo (the companion flying sitl-plant at real time) publishes on Zenoh; ``companion monitor
--once --json`` counts the state samples that reach a subscriber over WINDOW seconds, first with
no view, then with ``companion view`` subscribed (its CPU from its own getrusage summary).
Loopback only, multicast scouting off. Run: ``python benchmarks/bench_view.py``.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time

WINDOW = 20.0


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


def main() -> None:
    ep = f"tcp/127.0.0.1:{port()}"
    demo = companion("demo", "--speedup", "1", "--duration", "200", "--no-plot", "--no-log",
                     "--zenoh-listen", ep, "--no-zenoh-scouting", "-q")
    try:
        time.sleep(5)
        without = rate(ep)
        view = companion("view", "--zenoh-connect", ep, "--no-zenoh-scouting", "--web-port",
                         str(port()), "--grpc-port", str(port()), "--json",
                         "--duration", str(WINDOW + 15))
        view.stdout.readline()                      # serving
        with_view = rate(ep)
        out, _ = view.communicate(timeout=120)
        summary = json.loads(out.strip().splitlines()[-1])
    finally:
        demo.terminate()
        demo.communicate(timeout=30)
    print(f"state samples/s reaching a subscriber: without the view {without:.1f}, "
          f"with it {with_view:.1f}")
    print(f"view: {summary['samples']} samples, {summary['frames']} frames, "
          f"{summary['cpu_s']:.2f} s CPU over {summary['wall_s']:.1f} s = "
          f"{100 * summary['cpu_s'] / summary['wall_s']:.1f} % of one core (no browser open)")


if __name__ == "__main__":
    main()
