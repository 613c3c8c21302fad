"""Telemetry-to-setpoint latency of the companion over UDP on loopback, at 40 Hz and 1 kHz.

For each rate, starts ``sitl-plant`` paced in real time (loop rate high enough to grant the
rate) and runs the companion's session (the code behind ``companion run``) in this process on
the paper's ellipse, then prints:

* latency, read -> sent: companion wall time from reading a LOCAL_POSITION_NED to having sent
  its setpoint (what ``companion run --json`` reports as latency_p50/p99/max_ms);
* age at send: wall time of each send minus the sample's vehicle time, less the smallest such
  offset seen: how much later than the luckiest sample each answer left, so waiting in the
  socket, wake-ups and falling behind all count (meaningful only because the plant runs at
  real time);
* missed cycles: telemetry periods with no timely setpoint = gaps in the samples (lost or
  refused) + overruns (read -> sent longer than a period); ``late`` = age at send > a period.

Also the in-process cost of each piece of the per-sample hot path. Prints figures; asserts
nothing. Run: .venv/bin/python benchmarks/bench_latency.py [--seconds 60] [--rates 40,1000]
"""

from __future__ import annotations

import argparse
import math
import os
import socket
import subprocess
import sys
import tempfile
import time
from array import array
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
os.environ["MAVLINK20"] = "1"

from companion import mission as missions  # noqa: E402
from companion.live.events import LoopRecord, StatusEvent  # noqa: E402
from companion.live.link import LinkConfig  # noqa: E402
from companion.live.policy import GainOptions  # noqa: E402
from companion.live.runner import RunnerConfig  # noqa: E402
from companion.live.session import RunSettings, fly  # noqa: E402


class AgeSink:
    """Wall time of each record (just after the send) against the sample's vehicle time."""

    def __init__(self) -> None:
        self.offsets = array("d")

    def record(self, rec: LoopRecord) -> None:
        self.offsets.append(time.perf_counter() - rec.vehicle_time)

    def status(self, event: StatusEvent) -> None:
        pass

    def close(self) -> None:
        pass


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def pct(sorted_values, q: float) -> float:
    if not sorted_values:
        return math.nan
    return sorted_values[min(len(sorted_values) - 1, max(0, math.ceil(q / 100 * len(sorted_values)) - 1))]


def run_rate(rate: float, seconds: float) -> None:
    port = free_port()
    loop_rate = max(50.0, math.ceil(rate / 0.8) + 1)
    plant = subprocess.Popen([sys.executable, "-m", "sitl_plant", "--connect",
                              f"udpout:127.0.0.1:{port}", "--d-cen", "0.3",
                              "--loop-rate", f"{loop_rate:g}"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    ages = AgeSink()
    try:
        with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
            f.write(f'name = "bench"\nduration = {seconds}\n[trajectory]\nkind = "ellipse"\n'
                    "f_r = 0.12\n")
        mission = missions.load(f.name)
        settings = RunSettings(link=LinkConfig(url=f"udpin:127.0.0.1:{port}"), mission=mission,
                               runner=RunnerConfig(arm=True), gains=GainOptions(rate=rate))
        r = fly(settings, sinks=[ages])
    finally:
        plant.terminate()
        plant.wait()
        os.unlink(f.name)
    period = 1.0 / rate
    offsets = sorted(ages.offsets)
    base = offsets[0] if offsets else 0.0
    age = [o - base for o in offsets]
    late = sum(1 for a in age if a > period)
    print(f"\n{rate:g} Hz for {seconds:g} s ({r.reason}): {r.cycles} cycles at "
          f"{r.loop_rate_hz:.2f} Hz, f_cost {r.f_cost:.3f}, steady RMS {r.steady_rms:.4f} m")
    print(f"  latency read -> sent  p50 {r.latency_p50_ms:.3f} ms  p99 {r.latency_p99_ms:.3f} ms"
          f"  max {r.latency_max_ms:.3f} ms")
    print(f"  age at send          p50 {pct(age, 50) * 1e3:.3f} ms  p99 {pct(age, 99) * 1e3:.3f} ms"
          f"  max {max(age, default=math.nan) * 1e3:.3f} ms   (above the best sample's)")
    print(f"  missed cycles {r.missed_cycles} (gaps {r.extra['missed_gaps']}, overruns "
          f"{r.overruns}); late {late}; backlog {r.extra['backlog']}; refused "
          f"{sum(r.telemetry_rejected.values())}")


def hot_path_costs(n: int = 20000) -> None:
    """In-process cost of each step a sample goes through (no network wait)."""
    from pymavlink import mavutil
    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    from companion.core.limits import Limits
    from companion.core.pzc import PZCTracker
    from companion.core.signals import Measurement
    from companion.live.telemetry import TelemetryCheck

    out = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = [out.local_position_ned_encode(k, 1.0, 2.0, 0.0, 0.1, 0.2, 0.0).pack(out)
              for k in range(n)]
    parser = mavlink2.MAVLink(None)
    t0 = time.perf_counter()
    msgs = [parser.parse_char(b) for b in frames]
    t_parse = (time.perf_counter() - t0) / n

    check = TelemetryCheck(1, 1)
    check._att_ms = 0   # a valid attitude held (white-box: this measures position() alone)
    t0 = time.perf_counter()
    for m in msgs:
        check.position(m)
    t_check = (time.perf_counter() - t0) / n

    traj = missions.paper_ellipse().anchored(0.1, 0.2, 0.3)
    tracker = PZCTracker(limits=Limits(6.0, 6.0))
    t0 = time.perf_counter()
    for k in range(n):
        t = k * 1e-3
        tracker.step(t, Measurement(0.1, 0.2, 0.3), traj.sample(t))
    t_step = (time.perf_counter() - t0) / n

    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{sink.getsockname()[1]}",
                                      dialect="ardupilotmega")
    t0 = time.perf_counter()
    for k in range(n):
        conn.mav.set_position_target_local_ned_send(k, 1, 1, 8, 1511, 0, 0, 0, 1.0, 0, 0, 0, 0,
                                                    0, 0, 0.5)
        if k % 200 == 199:
            while True:   # keep the receive buffer from filling
                try:
                    sink.recv(4096, socket.MSG_DONTWAIT)
                except BlockingIOError:
                    break
    t_send = (time.perf_counter() - t0) / n
    conn.close()
    sink.close()
    print("hot path in-process, per sample (us): "
          f"parse LOCAL_POSITION_NED {t_parse * 1e6:.1f}, telemetry check {t_check * 1e6:.1f}, "
          f"reference + filter + PZC {t_step * 1e6:.1f}, encode + sendto (nobody waiting) "
          f"{t_send * 1e6:.1f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=60.0, help="per rate (default 60)")
    p.add_argument("--rates", default="40,1000", help="comma-separated Hz (default 40,1000)")
    p.add_argument("--fifo", action="store_true",
                   help="run the companion under SCHED_FIFO (needs CAP_SYS_NICE)")
    args = p.parse_args()
    if args.fifo:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
            print("companion under SCHED_FIFO priority 10")
        except (PermissionError, AttributeError, OSError) as exc:
            print(f"SCHED_FIFO not available ({exc}); default scheduling")
    print(f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    hot_path_costs()
    for rate in (float(x) for x in args.rates.split(",")):
        run_rate(rate, args.seconds)


if __name__ == "__main__":
    main()
