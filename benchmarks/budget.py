"""The companion's budget on a board: CPU, memory, start-up and import time of ``companion run``.

Runs the real processes: ``sitl-plant`` (preset ardupilot-skid: ArduPilot's 20/20/20/40 ms
telemetry at 40 Hz, paced in real time) and ``companion run`` at 40 Hz on an ellipse, with
flight logs on and Zenoh on (a peer with multicast scouting off, publishing every cycle to a
``companion monitor`` connected over TCP on loopback, so each state message really leaves
the process). Prints:

* CPU as a percentage of one core, while tracking (from /proc/PID/stat, user + system, all
  threads) and over the whole process life (wait4's rusage);
* resident memory: VmRSS while tracking (median) and the peak (VmHWM = rusage maxrss);
* start-up: wall time from launching the process to the first vehicle heartbeat, the first
  LOCAL_POSITION_NED, the first setpoint and the first tracking setpoint (GUIDED and armed),
  read from the run's own .tlog (both directions, stamped with the wall clock); the plant
  streams before the companion starts, so telemetry is flowing;
* import time of the ``run`` path: ``python -X importtime`` of a short real run (every module
  the process imported, up to the end) and a timed import of the same modules in a fresh
  interpreter; and whether anything heavy (plotting, tqdm, scipy, ...) was imported;
* the same run again pinned to one core (``--cpu``) under a CPU quota (``--quota`` %, 25 by
  default: roughly one core of a small board), with loop rate, missed cycles, overruns,
  latency and how often the quota throttled the process. It says how the quota was applied:
  cgroup v2 ``cpu.max``, cgroup v1 ``cpu.cfs_quota_us`` (both need write access to
  /sys/fs/cgroup), ``systemd-run --scope -p CPUQuota=`` (systemd as PID 1), or, failing all of
  these, a SIGSTOP / SIGCONT duty cycle (an approximation, named as such).

Targets (issue 43, tightening issue 13's 5 % and 1 s): CPU <= 3 % of a core, RSS <= 80 MB,
import <= 0.5 s with nothing heavy imported, 40 Hz held with no missed cycle under the quota. Prints figures and a verdict per target; asserts nothing.

Run: .venv/bin/python benchmarks/budget.py [--seconds 60] [--quota 25] [--cpu 0]
     [--quota-method auto|cgroup|systemd|duty] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
VEHICLE = ROOT / "companion" / "sim" / "vehicles" / "ardupilot_skid.toml"
CLK_TCK = os.sysconf("SC_CLK_TCK")
HEAVY = ("matplotlib", "scipy", "pandas", "PIL", "tqdm", "IPython", "sympy", "numba",
         "cryptography")
GUIDED = 15                     # ArduPilot Rover custom_mode
ARMED = 128                     # MAV_MODE_FLAG_SAFETY_ARMED
# The companion speaks as a component of the vehicle's own system (the onboard-computer
# convention), so its messages are told apart by component: LinkConfig.source_component.
COMPANION_COMPID = 191          # MAV_COMP_ID_ONBOARD_COMPUTER
TARGETS = {"cpu_pct": 3.0, "rss_mb": 80.0, "import_s": 0.5}


def free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def mission_file(directory: Path, seconds: float) -> Path:
    """The paper's ellipse at 0.04 Hz: within a stock skid-steer rover's reach."""
    path = directory / "budget.toml"
    path.write_text(f'name = "budget"\nframe = "start"\nduration = {seconds}\n'
                    '[trajectory]\nkind = "ellipse"\nf_r = 0.04\nax = 6.0\nbx = -1.0\n'
                    'ay = 2.0\nby = 3.0\n')
    return path


def clean_env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("ZENOH_CONFIG", None)     # the flags below say everything about Zenoh
    # As on a board: once this process has read a .tlog, pymavlink has exported
    # MAVLINK_DIALECT=all, which would make the companion load that dialect too.
    env.pop("MAVLINK_DIALECT", None)
    env["MAVLINK20"] = "1"
    return env


# --------------------------------------------------------------------------- CPU quota

@dataclass
class Quota:
    """How the companion is constrained: ``how`` (printed), ``wrap`` (argv prefix),
    ``preexec`` (run in the child before exec), ``attach(pid)`` after start, ``stats()``
    (throttling counters) and ``close()``."""
    how: str
    wrap: list[str] = field(default_factory=list)
    preexec: Callable[[], None] | None = None
    attach: Callable[[int], None] = lambda pid: None
    stats: Callable[[], dict] = dict
    close: Callable[[], None] = lambda: None


def _read_kv(path: Path) -> dict:
    try:
        return {k: int(v) for k, v in (line.split() for line in path.read_text().splitlines())}
    except (OSError, ValueError):
        return {}


def make_quota(percent: float, cpu: int, method: str = "auto") -> Quota:
    period = 100_000
    quota_us = int(period * percent / 100)
    pin = f"pinned to CPU {cpu}"

    def affinity() -> None:
        os.sched_setaffinity(0, {cpu})

    name = f"pzc-budget-{os.getpid()}"

    def cgroup(group: Path, settings: dict[str, str], how: str) -> Quota | None:
        """A fresh cgroup with these files written, or None (and nothing left behind)."""
        try:
            group.mkdir()
        except OSError:
            return None
        try:
            for key, value in settings.items():
                (group / key).write_text(value)
        except OSError:
            group.rmdir()
            return None
        procs = group / "cgroup.procs"

        def enter() -> None:            # in the child, before exec: it and its threads
            procs.write_text(str(os.getpid()))
            affinity()
        return Quota(f"{how}, {pin} (sched_setaffinity)", preexec=enter,
                     stats=lambda: _read_kv(group / "cpu.stat"), close=group.rmdir)

    if method in ("auto", "cgroup"):
        # cgroup v2: a child of our own cgroup, where the parent hands the cpu controller down.
        unified = Path("/sys/fs/cgroup")
        quota = None
        if (unified / "cgroup.controllers").exists():
            try:
                own = open("/proc/self/cgroup").read().strip().split("::", 1)[1].strip()
                parent = unified / Path(own).relative_to("/")
                if "cpu" in (parent / "cgroup.subtree_control").read_text().split():
                    group = parent / name
                    quota = cgroup(group, {"cpu.max": f"{quota_us} {period}"},
                                   f"cgroup v2 {group}/cpu.max = '{quota_us} {period}' "
                                   f"({percent:g} % of one core)")
            except (OSError, ValueError, IndexError):
                quota = None
        # cgroup v1: the cpu controller's CFS bandwidth.
        v1 = Path("/sys/fs/cgroup/cpu")
        if quota is None and (v1 / "cpu.cfs_quota_us").exists():
            group = v1 / name
            quota = cgroup(group, {"cpu.cfs_period_us": str(period),
                                   "cpu.cfs_quota_us": str(quota_us)},
                           f"cgroup v1 {group}: cpu.cfs_quota_us = {quota_us} per "
                           f"cpu.cfs_period_us = {period} ({percent:g} % of one core)")
        if quota is not None:
            return quota
    # systemd as PID 1: a transient scope.
    if (method in ("auto", "systemd") and Path("/run/systemd/system").is_dir()
            and shutil.which("systemd-run")):
        user = [] if os.geteuid() == 0 else ["--user"]
        return Quota(f"systemd-run {' '.join(user)} --scope -p CPUQuota={percent:g}% "
                     f"-p AllowedCPUs={cpu}, {pin}",
                     wrap=["systemd-run", *user, "--quiet", "--scope",
                           "-p", f"CPUQuota={percent:g}%", "-p", f"AllowedCPUs={cpu}",
                           "taskset", "-c", str(cpu)])
    if method not in ("auto", "duty"):
        raise SystemExit(f"--quota-method {method}: not available here")
    # No way to a real quota: what cpulimit does. Every period, watch the process's CPU time
    # (all threads, ns, /proc/PID/task/*/schedstat) and SIGSTOP it for the rest of the period
    # once it has used its share; SIGCONT at the period's end. Coarser than CFS (polled every
    # 2 ms, stopped as a whole), so named as an approximation.
    stop = threading.Event()
    stopped = {"periods": 0, "throttled": 0, "throttled_ns": 0}

    def cpu_ns(pid: int) -> int:
        total = 0
        for tid in os.listdir(f"/proc/{pid}/task"):
            try:
                total += int(open(f"/proc/{pid}/task/{tid}/schedstat").read().split()[0])
            except (OSError, ValueError, IndexError):
                pass
        return total

    def limit(pid: int) -> None:
        period_s, budget_ns = period / 1e6, quota_us * 1000

        def loop() -> None:
            try:
                while not stop.is_set():
                    start, base = time.monotonic(), cpu_ns(pid)
                    stopped["periods"] += 1
                    while (left := period_s - (time.monotonic() - start)) > 0:
                        if cpu_ns(pid) - base >= budget_ns:
                            os.kill(pid, signal.SIGSTOP)
                            time.sleep(left)
                            os.kill(pid, signal.SIGCONT)
                            stopped["throttled"] += 1
                            stopped["throttled_ns"] += int(left * 1e9)
                            break
                        time.sleep(0.002)
            except (ProcessLookupError, FileNotFoundError):
                return
        threading.Thread(target=loop, daemon=True).start()
    return Quota(f"APPROXIMATION (no writable cgroup, no systemd): SIGSTOP / SIGCONT limiter "
                 f"as cpulimit does, {percent:g} % of CPU time per {period / 1000:g} ms, {pin}",
                 preexec=affinity, attach=limit, close=stop.set,
                 stats=lambda: {"nr_periods": stopped["periods"],
                                "nr_throttled": stopped["throttled"],
                                "throttled_time": stopped["throttled_ns"]})


# --------------------------------------------------------------------------- one run

@dataclass
class Sample:
    t: float        # wall clock (time.time)
    ticks: int      # utime + stime, clock ticks
    rss_kb: int
    threads: int
    throttled: int = 0      # the quota's nr_throttled so far


def proc_sample(pid: int) -> Sample | None:
    try:
        stat = open(f"/proc/{pid}/stat").read()
        status = open(f"/proc/{pid}/status").read()
    except OSError:
        return None
    fields = stat[stat.rindex(")") + 2:].split()
    if fields[0] == "Z":        # exited, not yet reaped
        return None
    rss = re.search(r"^VmRSS:\s+(\d+) kB", status, re.M)
    threads = re.search(r"^Threads:\s+(\d+)", status, re.M)
    return Sample(time.time(), int(fields[11]) + int(fields[12]), int(rss.group(1)) if rss else 0,
                  int(threads.group(1)) if threads else 0)


def tlog_times(path: str) -> dict[str, float | None]:
    """Wall times (time.time) of the run's first events, from its .tlog."""
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil
    log = mavutil.mavlink_connection(path, dialect="ardupilotmega")
    out: dict[str, float | None] = {"heartbeat": None, "telemetry": None, "setpoint": None,
                                    "tracking": None, "last_setpoint": None}
    engaged = False
    while True:
        msg = log.recv_match()
        if msg is None:
            break
        kind, t = msg.get_type(), msg._timestamp
        ours = msg.get_srcComponent() == COMPANION_COMPID
        if kind == "HEARTBEAT" and not ours:
            out["heartbeat"] = out["heartbeat"] or t
            engaged = bool(msg.base_mode & ARMED) and msg.custom_mode == GUIDED
        elif kind == "LOCAL_POSITION_NED" and not ours:
            out["telemetry"] = out["telemetry"] or t
        elif kind == "SET_POSITION_TARGET_LOCAL_NED" and ours:
            out["setpoint"] = out["setpoint"] or t
            if engaged:
                out["tracking"] = out["tracking"] or t
            out["last_setpoint"] = t
    return out


@dataclass
class RunFigures:
    result: dict
    cpu_tracking_pct: float
    cpu_life_pct: float
    cpu_s: float
    wall_s: float
    rss_tracking_mb: float
    rss_peak_mb: float
    threads: int
    startup_ms: dict
    zenoh_state_msgs: int | None
    zenoh_lost: int | None
    throttle: dict


def fly(seconds: float, quota: Quota | None, work: Path, plant_cpus: set[int] | None
        ) -> RunFigures:
    udp, zport = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_STREAM)
    env = clean_env()
    mission = mission_file(work, seconds)
    logs = work / ("logs-quota" if quota else "logs")
    plant = subprocess.Popen(
        [str(BIN / "sitl-plant"), "--connect", f"udpout:127.0.0.1:{udp}", "--preset",
         "ardupilot-skid"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
        preexec_fn=(lambda: os.sched_setaffinity(0, plant_cpus)) if plant_cpus else None)
    monitor = subprocess.Popen(
        [str(BIN / "companion"), "monitor", "--zenoh-listen", f"tcp/127.0.0.1:{zport}",
         "--no-zenoh-scouting", "--once", "--json", "--wait", "100000"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env,
        preexec_fn=(lambda: os.sched_setaffinity(0, plant_cpus)) if plant_cpus else None)
    companion = None
    samples: list[Sample] = []
    try:
        time.sleep(1.5)     # the plant streaming and the monitor listening before we start
        argv = [str(BIN / "companion"), "run", "--connect", f"udpin:127.0.0.1:{udp}",
                "--mission", str(mission), "--arm", "--rate", "40", "--vehicle", str(VEHICLE),
                "--log-dir", str(logs), "--no-zenoh-scouting",
                "--zenoh-connect", f"tcp/127.0.0.1:{zport}", "--json", "-q"]
        started = time.time()
        companion = subprocess.Popen((quota.wrap if quota else []) + argv,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     env=env, preexec_fn=quota.preexec if quota else None)
        if quota:
            quota.attach(companion.pid)
        out = {"stdout": "", "stderr": ""}

        def drain(name: str) -> None:
            out[name] = getattr(companion, name).read()
        readers = [threading.Thread(target=drain, args=(n,), daemon=True) for n in out]
        for r in readers:
            r.start()
        # Sample /proc while it runs; wait4 then reaps it and gives the exact totals.
        pid = companion.pid
        deadline = time.monotonic() + seconds + 120
        while time.monotonic() < deadline:
            s = proc_sample(pid)
            if s is None:
                break
            if quota:
                s.throttled = quota.stats().get("nr_throttled", 0)
            samples.append(s)
            time.sleep(0.1)
        _, status, usage = os.wait4(pid, 0)
        companion.returncode = os.waitstatus_to_exitcode(status)
        ended = time.time()
        for r in readers:
            r.join(10)
    finally:
        for p in (companion, plant):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
        if monitor.poll() is None:
            monitor.send_signal(signal.SIGTERM)
        try:
            mon_out, _ = monitor.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            monitor.kill()
            mon_out, _ = monitor.communicate()
    stdout, stderr = out["stdout"], out["stderr"]
    if not stdout.strip():
        raise SystemExit(f"companion run printed no result (exit {companion.returncode}):\n"
                         f"{stderr}")
    result = json.loads(stdout.strip().splitlines()[-1])
    times = tlog_times(result["tlog"])
    track0, track1 = (times["tracking"] or started) + 1.0, times["last_setpoint"] or ended
    window = [s for s in samples if track0 <= s.t <= track1]
    if len(window) >= 2:
        a, b = window[0], window[-1]
        cpu_tracking = (b.ticks - a.ticks) / CLK_TCK / (b.t - a.t) * 100
        rss_tracking = statistics.median(s.rss_kb for s in window) / 1024
    else:
        cpu_tracking, rss_tracking = math.nan, math.nan
    cpu_s = usage.ru_utime + usage.ru_stime
    threads = max((s.threads for s in samples), default=0)
    throttle = quota.stats() if quota else {}
    if quota and len(window) >= 2:
        throttle["throttled_while_tracking"] = window[-1].throttled - window[0].throttled
        throttle["tracking_periods"] = int((window[-1].t - window[0].t) * 10)
    state_msgs = lost = None
    try:
        snap = json.loads(mon_out.strip().splitlines()[-1])
        vehicle = next(v for v in snap["vehicles"] if v["vehicle_id"] == "rover1")
        state_msgs, lost = vehicle["state_msgs"], vehicle["lost"]
    except (ValueError, IndexError, StopIteration, KeyError):
        pass

    def ms(t: float | None) -> float | None:
        return None if t is None else (t - started) * 1e3
    return RunFigures(
        result=result, cpu_tracking_pct=cpu_tracking, cpu_life_pct=cpu_s / (ended - started) * 100,
        cpu_s=cpu_s, wall_s=ended - started, rss_tracking_mb=rss_tracking,
        rss_peak_mb=usage.ru_maxrss / 1024, threads=threads,
        startup_ms={"heartbeat": ms(times["heartbeat"]), "telemetry": ms(times["telemetry"]),
                    "setpoint": ms(times["setpoint"]), "tracking": ms(times["tracking"])},
        zenoh_state_msgs=state_msgs, zenoh_lost=lost,
        throttle=throttle)


# --------------------------------------------------------------------------- imports

def import_figures(work: Path) -> dict:
    """``-X importtime`` of a short real run, then a timed import of the same top-level
    modules in fresh interpreters (no importtime overhead)."""
    udp = free_port(socket.SOCK_DGRAM)
    env = clean_env()
    plant = subprocess.Popen([str(BIN / "sitl-plant"), "--connect", f"udpout:127.0.0.1:{udp}",
                              "--preset", "ardupilot-skid"], stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, env=env)
    try:
        time.sleep(1.0)
        proc = subprocess.run(
            [sys.executable, "-X", "importtime", "-m", "companion", "run", "--connect",
             f"udpin:127.0.0.1:{udp}", "--mission", str(mission_file(work, 3.0)), "--arm",
             "--rate", "40", "--vehicle", str(VEHICLE), "--log-dir", str(work / "logs-import"),
             "--no-zenoh-scouting", "--zenoh-listen", "tcp/127.0.0.1:0", "-q", "--json"],
            capture_output=True, text=True, env=env, timeout=120, cwd=work)
    finally:
        plant.kill()
        plant.wait()
    rows = re.findall(r"^import time:\s+(\d+) \|\s+(\d+) \| (\s*)(\S+)$", proc.stderr, re.M)
    if not rows:
        raise SystemExit(f"no -X importtime output:\n{proc.stderr[-2000:]}")
    top = [(name, int(cum)) for _, cum, indent, name in rows if indent == ""]
    every = [name for *_, name in rows]
    heavy = sorted({n.split(".")[0] for n in every if n.split(".")[0] in HEAVY})
    # The same modules (skipping the interpreter's own start-up ones) in a fresh interpreter.
    code = ("import time, importlib\nt = time.perf_counter()\n"
            f"for name in {[n for n, _ in top]!r}:\n"
            "    try:\n        importlib.import_module(name)\n"
            "    except Exception:\n        pass\n"
            "import companion.cli\ncompanion.cli.build_parser()\n"
            "print(time.perf_counter() - t)\n")
    timed = []
    for _ in range(5):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             env=env, cwd=work, check=True)
        timed.append(float(out.stdout.strip()))
    start = []
    for _ in range(5):
        t = time.perf_counter()
        subprocess.run([sys.executable, "-c", "pass"], env=env, check=True)
        start.append(time.perf_counter() - t)
    return {"importtime_total_s": sum(c for _, c in top) / 1e6,
            "largest": sorted(top, key=lambda r: -r[1])[:6],
            "modules": len(every), "heavy": heavy,
            "timed_import_s": statistics.median(timed),
            "interpreter_start_s": statistics.median(start)}


# --------------------------------------------------------------------------- report

def verdict(ok: bool) -> str:
    return "ok" if ok else "OVER"


def print_run(title: str, f: RunFigures) -> None:
    r = f.result
    print(f"\n{title}")
    print(f"  result        {r['reason']} (exit {r['exit_code']}), {r['cycles']} cycles at "
          f"{r['loop_rate_hz']:.2f} Hz (asked {r['rate_requested_hz']:g}, accepted "
          f"{r['rate_accepted_hz']:g}); missed cycles {r['missed_cycles']} (gaps "
          f"{r['missed_gaps']}, overruns {r['overruns']}); backlog {r['backlog']}")
    print(f"  latency       read -> sent p50 {r['latency_p50_ms']:.3f} ms, p99 "
          f"{r['latency_p99_ms']:.3f} ms, max {r['latency_max_ms']:.3f} ms")
    print(f"  CPU           {f.cpu_tracking_pct:.2f} % of one core while tracking "
          f"[{verdict(f.cpu_tracking_pct <= TARGETS['cpu_pct'])}, target <= "
          f"{TARGETS['cpu_pct']:g} %]; {f.cpu_life_pct:.2f} % over its life "
          f"({f.cpu_s:.2f} CPU s in {f.wall_s:.1f} s, start-up included)")
    print(f"  memory        RSS {f.rss_tracking_mb:.1f} MB while tracking, peak (VmHWM) "
          f"{f.rss_peak_mb:.1f} MB [{verdict(f.rss_peak_mb <= TARGETS['rss_mb'])}, target <= "
          f"{TARGETS['rss_mb']:g} MB]; {f.threads} threads")
    s = f.startup_ms

    def ms(v):
        return "n/a" if v is None else f"{v:.0f} ms"
    print(f"  start-up      from launch: first heartbeat {ms(s['heartbeat'])}, first "
          f"LOCAL_POSITION_NED {ms(s['telemetry'])}, first setpoint {ms(s['setpoint'])}, "
          f"first tracking setpoint (GUIDED, armed) {ms(s['tracking'])}")
    print(f"  zenoh         {f.zenoh_state_msgs} state messages received by the monitor, "
          f"{f.zenoh_lost} lost; flight log {Path(r['tlog']).name} + .csv")
    if f.throttle:
        t = f.throttle
        throttled_s = t.get("throttled_time", t.get("throttled_usec", 0) * 1000) / 1e9
        print(f"  quota         throttled in {t.get('nr_throttled')} of {t.get('nr_periods')} "
              f"periods, {throttled_s:.3f} s in total; while tracking in "
              f"{t.get('throttled_while_tracking')} of about {t.get('tracking_periods')}")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=60.0, help="mission length (default 60)")
    p.add_argument("--quota", type=float, default=25.0, help="CPU quota, %% of one core (25)")
    p.add_argument("--cpu", type=int, default=0, help="the core to pin to (default 0)")
    p.add_argument("--quota-method", choices=("auto", "cgroup", "systemd", "duty"),
                   default="auto", help="how to apply the quota (default: the first that "
                   "works of cgroup v2, cgroup v1, systemd-run, the duty-cycle approximation)")
    p.add_argument("--json", action="store_true", help="also print the figures as JSON")
    args = p.parse_args()
    others = set(os.sched_getaffinity(0)) - {args.cpu}
    print(f"companion run at 40 Hz, ellipse {args.seconds:g} s, sitl-plant --preset "
          f"ardupilot-skid, flight logs on, Zenoh peer (scouting off) -> companion monitor on "
          f"loopback; {os.cpu_count()} CPUs, Python {sys.version.split()[0]}")
    with tempfile.TemporaryDirectory(prefix="pzc-budget-") as tmp:
        work = Path(tmp)
        imports = import_figures(work)
        print(f"\nimport of the run path: {imports['timed_import_s']:.3f} s timed in a fresh "
              f"interpreter (+ {imports['interpreter_start_s']:.3f} s interpreter start) "
              f"[{verdict(imports['timed_import_s'] <= TARGETS['import_s'])}, target <= "
              f"{TARGETS['import_s']:g} s]; -X importtime of a real run: "
              f"{imports['importtime_total_s']:.3f} s, {imports['modules']} modules")
        print("  largest: " + ", ".join(f"{n} {c / 1e3:.0f} ms" for n, c in imports["largest"]))
        print(f"  heavy modules imported ({', '.join(HEAVY)}): "
              f"{', '.join(imports['heavy']) or 'none'} [{verdict(not imports['heavy'])}, "
              "target: none]")
        free = fly(args.seconds, None, work, None)
        print_run("unconstrained (any core, no quota)", free)
        quota = make_quota(args.quota, args.cpu, args.quota_method)
        try:
            limited = fly(args.seconds, quota, work, others or None)
        finally:
            quota.close()
        print_run(f"under a quota: {quota.how}; plant and monitor on CPUs "
                  f"{sorted(others) or 'any'}", limited)
        r = limited.result
        why = [w for w, bad in (
            (f"ended {r['reason']}", r["reason"] != "mission_done"),
            (f"{r['missed_cycles']} missed cycles", r["missed_cycles"] != 0),
            (f"loop at {r['loop_rate_hz']:.2f} Hz", abs(r["loop_rate_hz"] - 40.0) >= 0.4)) if bad]
        print(f"  40 Hz held with no missed cycle: {'NO: ' + ', '.join(why) if why else 'yes'}"
              f" (load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs)")
        if args.json:
            print(json.dumps({"imports": imports, "free": free.__dict__,
                              "quota": {"how": quota.how, **limited.__dict__}}, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
