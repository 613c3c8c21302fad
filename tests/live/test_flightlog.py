"""Flight logs: written by default, read back by pymavlink and by ``companion plot``, and a
SIGKILL mid-mission loses at most 100 ms of them. Real processes over loopback UDP."""

from __future__ import annotations

import json
import os
import signal
import time
from functools import partial
from pathlib import Path

import pytest

from companion.live.flightlog import CSV_FIELDS
from sitl_plant.testing import PlantProcess
from testbed.fake_vehicle import is_zero
from testbed.missions import ellipse_mission
from testbed.process import ROOT, Companion, companion_cli
from testbed.safety import read_tlog
from testbed.udp_proxy import Proxy

ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


companion = partial(companion_cli, timeout=90.0, env=ENV)


@pytest.fixture(scope="module")
def demo_logs(tmp_path_factory):
    """One 10 s demo with the default log directory (./logs of the working directory)."""
    cwd = tmp_path_factory.mktemp("demo")
    p = companion("demo", "--no-zenoh", "--json", "--no-plot", "--duration", "10", cwd=cwd)
    assert p.returncode == 0, p.stderr
    return cwd, json.loads(p.stdout.strip().splitlines()[-1]), p.stderr


def test_demo_writes_both_logs_by_default_and_says_where(demo_logs):
    cwd, r, stderr = demo_logs
    tlog, csv = Path(cwd, r["tlog"]), Path(cwd, r["csv"])
    assert tlog.parent == csv.parent == Path(cwd, "logs")
    assert tlog.suffix == ".tlog" and csv.suffix == ".csv" and tlog.stem == csv.stem
    assert f"flight log: {r['tlog']} and {r['csv']}" in stderr
    frames, bad = read_tlog(tlog)
    assert bad == 0
    kinds = {(m.get_type(), m.get_srcComponent()) for _, m in frames}
    # both directions: the vehicle's telemetry (component 1) and the companion's setpoints
    # and commands (component 191 of the same system)
    assert {("LOCAL_POSITION_NED", 1), ("ATTITUDE", 1), ("HEARTBEAT", 1),
            ("SET_POSITION_TARGET_LOCAL_NED", 191), ("COMMAND_LONG", 191)} <= kinds
    setpoints = [m for _, m in frames if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
    assert len(setpoints) == r["setpoints_sent"]
    stamps = [t for t, _ in frames]
    assert stamps == sorted(stamps) and abs(stamps[-1] - time.time()) < 120
    lines = csv.read_text().splitlines()
    assert lines[0].split(",") == CSV_FIELDS
    loop = [line for line in lines[1:] if line.split(",")[-1] == ""]
    assert len(loop) == r["cycles"] == 400
    events = [line.split(",")[-1] for line in lines[1:] if line.split(",")[-1]]
    assert events[0].startswith("connected") and events[-1] == "stopped: mission_done"


def test_no_log_writes_nothing(tmp_path):
    p = companion("demo", "--no-zenoh", "--json", "--no-plot", "--duration", "2", "--no-log",
                  cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout.strip().splitlines()[-1])
    assert "tlog" not in r and not (tmp_path / "logs").exists()


def test_plot_draws_the_figures_and_agrees_with_the_live_metrics(demo_logs, tmp_path):
    cwd, r, _ = demo_logs
    p = companion("plot", str(Path(cwd, r["csv"])), "--out", str(tmp_path / "csv"), "--json")
    assert p.returncode == 0, p.stderr
    m = json.loads(p.stdout)
    assert m["f_cost"] == pytest.approx(r["f_cost"], rel=1e-4)
    assert m["steady_rms"] == pytest.approx(r["steady_rms"], rel=2e-2)
    names = {Path(f).name for f in m["figures"]}
    assert names == {"path.png", "xy.png", "speed_yaw_rate.png", "filter_errors.png"}
    assert all(Path(f).stat().st_size > 10_000 for f in m["figures"])
    # the .tlog has no reference: rebuilt from the mission, anchored like the companion does
    mission = ellipse_mission(tmp_path / "m.toml", 10.0)
    p = companion("plot", str(Path(cwd, r["tlog"])), "--out", str(tmp_path / "tlog"),
                  "--mission", str(mission))
    assert p.returncode == 0, p.stderr
    assert "tracking    f_cost" in p.stdout and "figure" in p.stdout
    f_cost = float(p.stdout.split("f_cost ")[1].split(",")[0])
    assert f_cost == pytest.approx(r["f_cost"], rel=2e-2)
    assert len(list((tmp_path / "tlog").glob("*.png"))) == 3
    # without the mission: figures of what was measured, metrics n/a
    p = companion("plot", str(Path(cwd, r["tlog"])), "--out", str(tmp_path / "bare"))
    assert p.returncode == 0 and "f_cost n/a" in p.stdout


@pytest.mark.parametrize("name, content, expect", [
    ("missing.tlog", None, "no such file"),
    ("notes.txt", b"hello", "expected a .csv or .tlog"),
    ("other.csv", b"a,b,c\n1,2,3\n", "not a companion flight-log CSV"),
    # random bytes: pymavlink reads through them (no pose samples) or trips while opening the
    # file (about one time in eight): either way one line naming the file
    ("garbage.tlog", os.urandom(4000), ("no pose samples", "no MAVLink log in it")),
])
def test_plot_bad_logs_are_one_line_errors(tmp_path, name, content, expect):
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    p = companion("plot", str(path), "--out", str(tmp_path / "out"))
    assert p.returncode == 2, p.stdout + p.stderr
    lines = p.stderr.strip().splitlines()
    expect = (expect,) if isinstance(expect, str) else expect
    assert len(lines) == 1 and any(e in lines[0] for e in expect) and str(path) in lines[0], lines
    assert "Traceback" not in p.stderr


def test_log_dir_that_cannot_be_created_is_a_user_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    p = companion("run", "--no-zenoh", "--mission", "missions/circle.toml", "--log-dir",
                  str(blocker / "x"))
    assert p.returncode == 2 and "--log-dir" in p.stderr and "Traceback" not in p.stderr


# --- crash --------------------------------------------------------------------------------------
def _strict_csv(path: Path) -> tuple[list[list[str]], list[int]]:
    """Rows of the CSV and the line numbers that do not parse (as the flight-log writer wrote)."""
    lines = path.read_bytes().decode("utf-8", "replace").split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    rows, corrupt = [], []
    for n, line in enumerate(lines[1:], start=2):
        cells = line.split(",")
        ok = len(cells) == len(CSV_FIELDS)
        if ok and not cells[-1]:
            try:
                [float(c) for c in cells[:16]]
            except ValueError:
                ok = False
        (rows.append(cells) if ok else corrupt.append(n))
    return rows, corrupt, len(lines)


def test_sigkill_mid_mission_loses_at_most_100_ms_of_either_log(tmp_path):
    """The plant paced at real time (so vehicle time is wall time); the companion is killed with
    SIGKILL 4 s into tracking. The proxy saw every setpoint leave; both logs must hold every one
    sent up to 100 ms before the kill, and parse apart from possibly their last record."""
    mission = ellipse_mission(tmp_path / "m.toml", 60.0)
    logs = tmp_path / "logs"
    with Proxy() as proxy, \
            PlantProcess("--speedup", "1", "--d-cen", "0.3", port=proxy.plant_port), \
            Companion(proxy.companion_port, "--arm", "--no-zenoh", "--mission", str(mission),
                      "--log-dir", str(logs)) as comp:
        # (not -q: what it said is in a failure; 60 s for a loaded machine, as the MCAP twin)
        comp.wait_until(lambda: sum(1 for s in proxy.companion_sent(
            "SET_POSITION_TARGET_LOCAL_NED") if not is_zero(s.msg)) >= 160, 60.0,
            "160 tracking setpoints")
        os.kill(comp.proc.pid, signal.SIGKILL)
        comp.proc.wait(5.0)
        time.sleep(0.2)
        # Everything it sent, it sent before it died: the proxy's wall is when the proxy read a
        # frame, which under load can come after the kill (a cut at the kill's time dropped the
        # last logged setpoint once: KeyError in wall_of).
        sent = proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")
    assert comp.proc.returncode == -signal.SIGKILL
    wall_of = {s.msg.time_boot_ms: s.wall for s in sent}
    last_sent = sent[-1].wall

    csv_path, = logs.glob("*.csv")
    rows, corrupt, n_lines = _strict_csv(csv_path)
    assert set(corrupt) <= {n_lines}, f"corrupt CSV lines {corrupt} of {n_lines}"
    loop = [r for r in rows if not r[-1]]
    last_csv_ms = round(float(loop[-1][0]) * 1000)
    csv_missing = last_sent - wall_of[last_csv_ms]

    tlog_path, = logs.glob("*.tlog")
    frames, bad = read_tlog(tlog_path)
    assert bad <= 1, f"{bad} corrupt tlog frames"
    tlog_sps = [m for _, m in frames if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
    tlog_missing = last_sent - wall_of[tlog_sps[-1].time_boot_ms]
    # every setpoint up to the last logged one is in the tlog: nothing lost in the middle
    logged = {m.time_boot_ms for m in tlog_sps}
    upto = [ms for ms, w in wall_of.items() if w <= wall_of[tlog_sps[-1].time_boot_ms]]
    assert set(upto) <= logged
    print(f"\ncrash test: {len(sent)} setpoints sent before SIGKILL; missing from the CSV "
          f"{csv_missing * 1e3:.1f} ms, from the tlog {tlog_missing * 1e3:.1f} ms; "
          f"corrupt CSV lines {corrupt}, tlog BAD_DATA {bad}")
    assert csv_missing <= 0.100 and tlog_missing <= 0.100


def test_a_failsafe_that_stopped_the_rover_is_a_zero_setpoint_in_the_csv(tmp_path):
    """The CSV says what the vehicle was last asked: a failsafe that sent the zero setpoint
    records it (at the last sample heard, after that sample's own setpoint); one that left the
    vehicle to the autopilot's failsafe sent nothing and records nothing."""
    from companion.live.events import LoopRecord, StatusEvent
    from companion.live.flightlog import open_csv
    from companion.logs.logread import read

    def cycle(t: float) -> LoopRecord:
        return LoopRecord(t, t - 1.0, t, 0.0, 0.1, t, 0.0, 0.1, t, 0.0, 0.0, 0.0, 1.0, 0.5,
                          1.5, 0.4, "GUIDED", True)

    path = tmp_path / "run.csv"
    log = open_csv(str(path))
    for t in (1.0, 1.025, 1.05):
        log.record(cycle(t))
    log.status(StatusEvent("failsafe", "telemetry stale: no valid sample for 0.51 s", 1.05,
                           {"cause": "telemetry", "stop": True}))
    log.status(StatusEvent("resumed", "telemetry back", 1.6))
    for t in (1.6, 1.625):
        log.record(cycle(t))
    log.status(StatusEvent("failsafe", "autopilot failsafe: Failsafe (GCS)", 1.625,
                           {"cause": "autopilot", "stop": False}))
    log.close()
    flight = read(str(path))
    assert list(flight.t) == [1.0, 1.025, 1.05, 1.6, 1.625]
    assert list(flight.cmd_t) == [1.0, 1.025, 1.05, 1.05, 1.6, 1.625]
    assert list(flight.speed_cmd) == [1.5, 1.5, 1.5, 0.0, 1.5, 1.5]
    assert list(flight.yaw_rate_cmd) == [0.4, 0.4, 0.4, 0.0, 0.4, 0.4]
    assert [e for _, e in flight.events][0].startswith("failsafe: telemetry stale")
