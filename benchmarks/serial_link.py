"""What a serial link carries for ``companion run``: bytes a second each way, as a share of a UART.

For each baud rate, ``sitl-plant`` (paced at real time, so the byte rates are real) and
``companion run --connect /dev/pts/N --baud B`` fly the paper's ellipse (f_r 0.12 Hz, d_cen 0.3 m)
over two pseudo-terminals joined by testbed.pty_cable.PtyCable, which moves at most B / 10
bytes a second each way (8N1) and drops what a UART could not carry. Prints per baud rate: the
bytes a second each way and their share of the link, bytes dropped, the loop's rate and missed
cycles, the tracking figures and read -> sent latency. Asserts nothing.

Run: .venv/bin/python benchmarks/serial_link.py [--bauds 57600,115200,921600] [--seconds 30]
     [--rate 40]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from testbed.process import ROOT
from testbed.pty_cable import PtyCable


def fly(baud: int, seconds: float, rate: float, mission: Path) -> dict:
    with PtyCable(baud=baud) as cable:
        plant = subprocess.Popen(
            [sys.executable, "-m", "sitl_plant", "--connect", cable.paths[0], "--d-cen", "0.3",
             "--loop-rate", str(max(50.0, rate / 0.8))],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
        try:
            t0 = time.monotonic()
            comp = subprocess.run(
                [sys.executable, "-m", "companion", "run", "--connect", cable.paths[1],
                 "--baud", str(baud), "--mission", str(mission), "--rate", str(rate), "--arm",
                 "--json", "-q", "--no-log", "--no-zenoh"],
                capture_output=True, text=True, cwd=ROOT, timeout=seconds + 120)
            wall = time.monotonic() - t0
            carried, dropped = list(cable.carried), list(cable.dropped)
        finally:
            plant.terminate()
            plant.wait(10)
    lines = [line for line in comp.stdout.splitlines() if line.startswith("{")]
    result = json.loads(lines[-1]) if lines else {"reason": comp.stderr.strip()[-200:]}
    return {"result": result, "wall": wall, "carried": carried, "dropped": dropped,
            "exit": comp.returncode}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--bauds", default="57600,115200,921600")
    p.add_argument("--seconds", type=float, default=30.0, help="mission length (vehicle s)")
    p.add_argument("--rate", type=float, default=40.0, help="telemetry / control rate, Hz")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        mission = Path(tmp) / "ellipse.toml"
        mission.write_text(f'name = "paper ellipse {args.seconds:g} s"\nframe = "start"\n'
                           f'duration = {args.seconds}\n[trajectory]\nkind = "ellipse"\n'
                           'f_r = 0.12\n')
        print(f"paper ellipse, {args.seconds:g} s at {args.rate:g} Hz, real time, over a pty "
              "cable paced as 8N1 (bytes/s = baud / 10)")
        print(f"{'baud':>7} {'capacity':>9} {'plant->comp':>17} {'comp->plant':>17} "
              f"{'dropped':>8} {'loop Hz':>8} {'missed':>6} {'steady RMS':>10} {'f_cost':>7} "
              f"{'p50/p99 ms':>11} result")
        for baud in (int(b) for b in args.bauds.split(",")):
            run = fly(baud, args.seconds, args.rate, mission)
            r = run["result"]
            cap = baud / 10.0
            # The bytes of the tracked part and its set-up, over the companion's whole run.
            up, down = (c / run["wall"] for c in run["carried"])

            def num(key: str, fmt: str, r: dict = r) -> str:   # r bound now (B023)
                return format(r[key], fmt) if r.get(key) is not None else "n/a"
            print(f"{baud:>7} {cap:>7.0f}/s {up:>8.0f}/s {100 * up / cap:>5.1f} % "
                  f"{down:>8.0f}/s {100 * down / cap:>5.1f} % {sum(run['dropped']):>8} "
                  f"{num('loop_rate_hz', '.1f'):>8} {num('missed_cycles', 'd'):>6} "
                  f"{num('steady_rms', '.3f'):>8} m {num('f_cost', '.3f'):>7} "
                  f"{num('latency_p50_ms', '.2f'):>5}/{num('latency_p99_ms', '.2f'):<5} "
                  f"{r.get('reason')} (exit {run['exit']})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
