"""Zenoh telemetry figures: what publishing costs the loop, state latency, and fleet capacity.

1. put cost in the loop: the in-process time of ``Bus.record`` (JSON encode + non-blocking
   ``put``) with a subscriber in another session connected over TCP loopback, per call;
2. state-publication latency: a ``sitl-plant`` + ``companion run`` pair in real time publishing
   every cycle; a subscriber in this process takes, per state message, its callback's wall
   clock minus the payload's ``sent_at`` (taken by the companion right before encoding, so the
   figure is encode + put + transport + Zenoh's dispatch to the callback); p50 / p99 / max. The
   same run with ``--no-zenoh`` gives the loop's own telemetry-to-setpoint latency without
   publishing, for comparison;
3. fleet capacity: ``n`` plant + companion pairs at 20 Hz through one ``companion router`` with
   one ``companion monitor`` (testbed.zenoh_fleet.run_fleet), for growing ``n``; the largest ``n``
   with every mission done, no missed control cycle in any companion (gaps + overruns, as
   ``companion run --json`` counts them) and no state gap over 200 ms at the monitor; the
   router's and the monitor's CPU time. The transports take turns at each size, and one stops
   after two sizes in a row not held.

Each part runs once per transport of ``--transport`` (default both, side by side in one run):
``plain`` TCP, and ``tls``: mutual TLS with each process's own certificate from a fresh
``companion pki`` CA and the access control of its role (issue 15), what a secured fleet pays.
A transport named twice (``plain,tls,plain,tls``) repeats the put and latency parts: the
machine's own noise, side by side.

Prints figures; asserts nothing. Shared, 2-core machine: run it when the machine is quiet, and
read the figures as orders of magnitude.
Run: .venv/bin/python benchmarks/bench_zenoh.py [--seconds 10] [--rate 40] [--fleet 10,20,30]
     [--transport plain,tls]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import zenoh

from companion.bus.codec import decode
from companion.bus.config import BusOptions
from companion.bus.session import prepare
from companion.bus.vehicle import Bus
from companion.live.events import LoopRecord, StatusEvent
from testbed.missions import mission_file
from testbed.process import ROOT
from testbed.zenoh_fleet import (
    config,
    endpoint,
    free_tcp_port,
    make_pki,
    run_fleet,
    tls_endpoint,
    tls_isolated,
)

FLEET_CERTS = {"mon": "monitor", "rover1": "rover", "bench": "rover"}


class Transport:
    """Plain TCP, or mutual TLS with certificates from a CA made for this run."""

    def __init__(self, tls: bool, tmp: Path):
        self.tls, self.name = tls, "mutual TLS" if tls else "plain TCP"
        self.pki = make_pki(tmp / "pki", FLEET_CERTS) if tls else None
        self.isolated = tls_isolated(tmp) if tls else None

    def endpoint(self, port: int) -> str:
        return tls_endpoint(port) if self.tls else endpoint(port)

    def subscriber(self, port: int) -> zenoh.Config:
        """A listening session, as a monitor."""
        return config(listen=[self.endpoint(port)],
                      tls=(self.pki, "mon") if self.tls else None)

    def companion_flags(self, name: str) -> list[str]:
        if not self.tls:
            return ["--no-zenoh-scouting"]
        return ["--zenoh-tls", str(self.pki / name), "--zenoh-config", str(self.isolated)]

    def publisher(self, port: int) -> zenoh.Config:
        """The session ``companion run`` would open as rover ``bench``, connecting to ``port``."""
        if not self.tls:
            return config(connect=[endpoint(port)])
        return prepare(BusOptions(tls=str(self.pki / "bench"), roles=("rover",),
                                  connect=(tls_endpoint(port),),
                                  config_file=str(self.isolated))).config


def pct(values: list[float], q: float) -> float:
    if not values:
        return math.nan
    s = sorted(values)
    return s[min(len(s) - 1, max(0, math.ceil(q / 100 * len(s)) - 1))]


def put_cost(tr: Transport, n: int = 20000) -> None:
    port = free_tcp_port()
    got = [0]
    b = zenoh.open(tr.subscriber(port))
    a = zenoh.open(tr.publisher(port))
    try:
        b.declare_subscriber("rover/*/state", lambda s: got.__setitem__(0, got[0] + 1))
        time.sleep(0.3)
        bus = Bus(a, BusOptions(vehicle_id="bench"))
        bus.status(StatusEvent("connected", "bench", None, {"sysid": 1}))
        rec = LoopRecord(12.345, 3.21, 1.0, 2.0, 0.3, 1.01, 2.01, 0.31, 1.1, 2.1, 0.14, 0.02,
                         1.2, 0.3, 1.25, 0.4, "GUIDED", True)
        times = []
        clock = time.perf_counter
        for _ in range(n):
            t = clock()
            bus.record(rec)
            times.append(clock() - t)
            if len(times) % 50 == 0:
                time.sleep(0.001)     # ~1 kHz-like pacing, not a tight burst
        time.sleep(0.5)
        bus.close()
        us = [x * 1e6 for x in times]
        print(f"{tr.name:>10}: put cost in the loop (Bus.record: JSON encode + put, DROP), "
              f"{n} calls: "
              f"p50 {pct(us, 50):.1f} us, p99 {pct(us, 99):.1f} us, max {max(us):.0f} us; "
              f"{got[0]} of {n} received")
    finally:
        a.close()
        b.close()


def _pair(tmp: Path, rate: float, seconds: float, zenoh_args: list[str]) -> dict:
    from sitl_plant.testing import free_udp_port
    port = free_udp_port()
    mission = mission_file(tmp / "bench.toml", seconds)
    loop_rate = max(50.0, math.ceil(rate / 0.8) + 1)
    plant = subprocess.Popen([sys.executable, "-m", "sitl_plant", "--connect",
                              f"udpout:127.0.0.1:{port}", "--d-cen", "0.3",
                              "--loop-rate", f"{loop_rate:g}"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        out = subprocess.run([sys.executable, "-m", "companion", "run", "--connect",
                              f"udpin:127.0.0.1:{port}", "--mission", str(mission), "--arm",
                              "--json", "-q", "--rate", f"{rate:g}", *zenoh_args],
                             capture_output=True, text=True, timeout=seconds + 60, cwd=ROOT)
    finally:
        plant.terminate()
        plant.wait(5)
    lines = [line for line in out.stdout.splitlines() if line.startswith("{")]
    if not lines:
        raise SystemExit(f"companion run failed: {out.stderr[-1000:]}")
    return json.loads(lines[-1])


def latency(tr: Transport, rate: float, seconds: float) -> None:
    port = free_tcp_port()
    lat: list[float] = []
    lock = threading.Lock()

    def on_state(sample) -> None:
        rx = time.time()
        msg = decode(sample.payload.to_bytes(), "state")
        with lock:
            lat.append(rx - msg["sent_at"])

    with tempfile.TemporaryDirectory() as tmp:
        s = zenoh.open(tr.subscriber(port))
        try:
            s.declare_subscriber("rover/*/state", on_state)
            with_bus = _pair(Path(tmp), rate, seconds,
                             ["--zenoh-connect", tr.endpoint(port),
                              *tr.companion_flags("rover1")])
        finally:
            s.close()
        without = _pair(Path(tmp), rate, seconds, ["--no-zenoh"])
    ms = [x * 1e3 for x in lat]
    print(f"{tr.name:>10}: state latency, companion put -> subscriber callback (another "
          f"process, loopback, {rate:g} Hz for {seconds:g} s, {len(ms)} messages): "
          f"p50 {pct(ms, 50):.3f} ms, p99 {pct(ms, 99):.3f} ms, "
          f"max {max(ms, default=math.nan):.3f} ms")
    for name, r in (("with Zenoh publishing", with_bus), ("with --no-zenoh", without)):
        print(f"  loop {name:<22}: telemetry->setpoint p50 {r['latency_p50_ms']:.3f} ms, "
              f"p99 {r['latency_p99_ms']:.3f} ms, {r['cycles']} cycles, "
              f"{r['missed_cycles']} missed, sink errors {r.get('sink_errors', 0)}")


def fleet(sizes: list[int], rate: float, duration: float, kinds: list[str]) -> None:
    """Grow the fleet; at each size run each transport in turn (so a busier minute on the
    shared machine does not land on one of them only). A size is held when every mission is
    done with no missed control cycle in any companion (gaps + overruns, as ``companion run
    --json`` counts them); separately, when the monitor also saw no state gap over 200 ms (the
    monitor is one more process competing for the same 2 cores). A transport stops after two
    sizes in a row not held (one miss on a noisy machine is not a limit)."""
    names = {"plain": "plain TCP", "tls": "mutual TLS"}
    best = {k: [0, 0] for k in kinds}
    misses = {k: 0 for k in kinds}
    for n in sizes:
        for kind in dict.fromkeys(kinds):
            if misses[kind] >= 2:
                continue
            name = names[kind]
            with tempfile.TemporaryDirectory() as tmp:
                try:
                    # Arming waits until every process has started (~0.6 s of CPU each on
                    # 2 cores), so what is measured is the fleet running, not it starting.
                    f = run_fleet(n, Path(tmp), rate=rate, duration=duration,
                                  arm_delay=6.0 + 0.8 * n, timeout=120.0 + 2.0 * n,
                                  tls=kind == "tls")
                except Exception as exc:  # noqa: BLE001  (a fleet too big fails many ways)
                    print(f"{name:>10}: fleet {n:3d} at {rate:g} Hz: failed "
                          f"({type(exc).__name__}: {exc})"[:300], flush=True)
                    misses[kind] = 2
                    continue
            done = sum(1 for r in f.results if r and r["reason"] == "mission_done")
            missed = sum(r["missed_cycles"] for r in f.results if r)
            gap = max(f.gaps_ms.values(), default=math.inf)
            seen = len(f.snapshot["vehicles"])
            loop_ok = done == n and missed == 0
            gap_ok = loop_ok and gap < 200.0 and seen == n
            p99_lat = max((r["latency_p99_ms"] for r in f.results if r), default=math.nan)
            print(f"{name:>10}: fleet {n:3d} at {rate:g} Hz: {done}/{n} missions done, missed "
                  f"control cycles {missed}, worst loop p99 {p99_lat:.2f} ms; monitor saw "
                  f"{seen}, max state gap {gap:.0f} ms; CPU router {f.cpu_s['router']:.1f} s, "
                  f"monitor {f.cpu_s['monitor']:.1f} s; exit after SIGTERM "
                  f"{max(f.exit_s.values()):.2f} s; wall {f.wall_s:.0f} s", flush=True)
            misses[kind] = 0 if loop_ok else misses[kind] + 1
            if loop_ok:
                best[kind][0] = n
            if gap_ok:
                best[kind][1] = n
        if all(m >= 2 for m in misses.values()):
            break
    print(f"largest fleet held at {rate:g} Hz (sizes tried {sizes}): " + "; ".join(
        f"{names[k]}: {a or 'none'} with no missed control cycle, {b or 'none'} with also no "
        f"monitor gap over 200 ms" for k, (a, b) in best.items()), flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=10.0, help="latency run length (vehicle s)")
    p.add_argument("--rate", type=float, default=40.0, help="latency run rate (Hz)")
    p.add_argument("--fleet", default="10,20,30,40", help="fleet sizes to try, in order")
    p.add_argument("--fleet-rate", type=float, default=20.0)
    p.add_argument("--fleet-duration", type=float, default=10.0)
    p.add_argument("--skip", default="", help="comma list of parts to skip: put,latency,fleet")
    p.add_argument("--transport", default="plain,tls",
                   help="comma list: plain (TCP), tls (mutual TLS + access control); default both")
    args = p.parse_args()
    skip = set(filter(None, args.skip.split(",")))
    kinds = [k.strip() for k in args.transport.split(",") if k.strip()]
    if not kinds or set(kinds) - {"plain", "tls"}:
        p.error(f"--transport {args.transport}: a comma list of plain, tls")
    from importlib.metadata import version
    print(f"eclipse-zenoh {version('eclipse-zenoh')} / Python {sys.version.split()[0]}, "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        transports = [Transport(k == "tls", Path(tmp) / f"{i}-{k}") for i, k in enumerate(kinds)]
        if "put" not in skip:
            for tr in transports:
                put_cost(tr)
        if "latency" not in skip:
            for tr in transports:
                latency(tr, args.rate, args.seconds)
    if "fleet" not in skip:
        fleet([int(x) for x in args.fleet.split(",")], args.fleet_rate, args.fleet_duration,
              kinds)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, lambda *a: sys.exit(143))
    main()
