"""MCAP flight logs: ``companion log export`` round-trips a sitl-plant flight's .tlog and CSV
into MCAP that the ``mcap`` library reads back with every message count equal, and
``run --log-format mcap`` written live loses at most 100 ms to a real SIGKILL. Real processes
over loopback UDP, real files."""

from __future__ import annotations

import json
import os
import signal
import time
from collections import Counter
from functools import partial
from pathlib import Path

import pytest

from testbed.process import companion_cli

pytest.importorskip("mcap")
pytest.importorskip("foxglove")
from mcap.reader import NonSeekingReader, make_reader  # noqa: E402

from sitl_plant.testing import PlantProcess  # noqa: E402
from testbed.fake_vehicle import is_zero  # noqa: E402
from testbed.missions import ellipse_mission  # noqa: E402
from testbed.process import ROOT, Companion  # noqa: E402
from testbed.safety import read_tlog  # noqa: E402
from testbed.udp_proxy import Proxy  # noqa: E402

ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


companion = partial(companion_cli, timeout=120.0, env=ENV)


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    """A 10 s demo: the companion flying sitl-plant, its .tlog and CSV."""
    cwd = tmp_path_factory.mktemp("flight")
    p = companion("demo", "--no-zenoh", "--json", "--no-plot", "--duration", "10", cwd=cwd)
    assert p.returncode == 0, p.stderr
    return cwd, json.loads(p.stdout.strip().splitlines()[-1])


def _counts(path: Path) -> tuple[Counter, dict]:
    """Messages per topic as the mcap library reads them (indexed), and the file's schemas."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None, "a closed log has its summary"
        counts = Counter(ch.topic for _, ch, _ in reader.iter_messages())
        stats = {summary.channels[c].topic: n
                 for c, n in summary.statistics.channel_message_counts.items()}
        schemas = {summary.channels[c].topic: summary.schemas[summary.channels[c].schema_id]
                   for c in summary.channels}
    assert dict(counts) == stats
    return counts, schemas


def test_export_round_trips_a_flights_tlog_with_every_message_count_equal(flight, tmp_path):
    cwd, r = flight
    tlog = Path(cwd, r["tlog"])
    out = tmp_path / "flight.mcap"
    p = companion("log", "export", str(tlog), "--mcap", str(out), "--json")
    assert p.returncode == 0, p.stderr
    frames, bad = read_tlog(tlog)
    assert bad == 0
    in_tlog = Counter(m.get_type() for _, m in frames)
    counts, schemas = _counts(out)
    in_mcap = {t.split("/", 2)[2]: n for t, n in counts.items() if t.startswith("/mavlink/")}
    assert in_mcap == dict(in_tlog)
    assert sum(in_mcap.values()) == len(frames) > 1000
    assert counts["/rover/pose"] == in_tlog["LOCAL_POSITION_NED"]
    assert counts["/mavlink/SET_POSITION_TARGET_LOCAL_NED"] == r["setpoints_sent"]
    assert schemas["/rover/pose"].name == "foxglove.PoseInFrame"
    assert schemas["/rover/pose"].encoding == "protobuf"
    assert schemas["/rover/events"].name == "foxglove.Log"
    assert json.loads(p.stdout)["source"] == dict(in_tlog)
    # the values survive: the last setpoint's speed, as pymavlink decoded it
    sp = [m for _, m in frames if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
    with open(out, "rb") as f:
        last = [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(
            topics=["/mavlink/SET_POSITION_TARGET_LOCAL_NED"])][-1]
    assert last["vx"] == pytest.approx(sp[-1].vx) and last["time_boot_ms"] == sp[-1].time_boot_ms


def test_export_of_the_csv_keeps_every_row(flight, tmp_path):
    cwd, r = flight
    csv = Path(cwd, r["csv"])
    out = tmp_path / "loop.mcap"
    p = companion("log", "export", str(csv), "--mcap", str(out))
    assert p.returncode == 0, p.stderr
    lines = csv.read_text().splitlines()[1:]
    loops = [line for line in lines if not line.split(",")[-1]]
    events = [line for line in lines if line.split(",")[-1]]
    counts, schemas = _counts(out)
    assert counts["/rover/loop"] == len(loops) == r["cycles"]
    assert counts["/rover/events"] == len(events)
    assert counts["/rover/pose"] == counts["/rover/reference"] == len(loops)
    assert counts["/rover/reference_path"] == 1
    assert schemas["/rover/loop"].encoding == "jsonschema"
    assert schemas["/rover/reference_path"].name == "foxglove.PosesInFrame"


@pytest.mark.parametrize("name, content, expect", [
    ("missing.tlog", None, "no such file"),
    ("notes.txt", "hello", "expected a .csv or .tlog"),
    ("bad.csv", "a,b,c\n1,2,3\n", "not a companion flight-log CSV"),
])
def test_export_bad_input_is_one_line_error_and_writes_nothing(tmp_path, name, content, expect):
    log = tmp_path / name
    if content is not None:
        log.write_text(content)
    out = tmp_path / "out.mcap"
    p = companion("log", "export", str(log), "--mcap", str(out))
    assert p.returncode == 2 and expect in p.stderr and "Traceback" not in p.stderr, p.stderr
    assert not out.exists()


def test_sigkill_of_a_run_logging_mcap_loses_at_most_100_ms(tmp_path):
    """As the CSV's crash test: sitl-plant at real time, SIGKILL 4 s into tracking; the MCAP
    (no summary, no footer) still reads back every loop up to 100 ms before the kill."""
    mission = ellipse_mission(tmp_path / "m.toml", 60.0)
    logs = tmp_path / "logs"
    with Proxy() as proxy, \
            PlantProcess("--speedup", "1", "--d-cen", "0.3", port=proxy.plant_port), \
            Companion(proxy.companion_port, "--arm", "--no-zenoh", "--mission", str(mission),
                      "--log-dir", str(logs), "--log-format", "mcap") as comp:
        # (not -q: if it is slow to track, what it said is in the failure; 60 s for a loaded
        # machine, where 30 s once passed with nothing tracked beside two busy tunes)
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
    assert not list(logs.glob("*.csv"))
    path, = logs.glob("*.mcap")
    wall_of = {s.msg.time_boot_ms: s.wall for s in sent}
    loops = []
    with open(path, "rb") as f:
        try:
            for _, ch, m in NonSeekingReader(f).iter_messages(log_time_order=False):
                if ch.topic == "/rover/loop":
                    loops.append(json.loads(m.data))
        except Exception:  # noqa: BLE001 - the record the kill tore
            pass
    assert len(loops) >= 150
    last_ms = round(loops[-1]["vehicle_time"] * 1000)
    missing = sent[-1].wall - wall_of[last_ms]
    # nothing lost in the middle: every cycle's vehicle time up to the last one, in order
    times = [round(r["vehicle_time"] * 1000) for r in loops]
    assert times == sorted(times) and len(set(times)) == len(times)
    print(f"\nmcap crash test: {len(sent)} setpoints sent before SIGKILL, {len(loops)} loops "
          f"in the MCAP, missing {missing * 1e3:.1f} ms")
    assert missing <= 0.100


@pytest.mark.sitl
@pytest.mark.slow
def test_export_round_trips_an_ardupilot_sitl_flights_tlog(ardupilot, tmp_path):
    """A 15 s circle flown on ArduPilot Rover SITL, logged as MCAP live; its .tlog exported:
    every MAVLink message of every type is in the MCAP, counted by the mcap library."""
    from testbed.ardupilot import CompanionProcess
    from testbed.missions import circle_mission
    sitl = ardupilot(speedup=5)
    mission = circle_mission(tmp_path / "circle.toml", duration=15.0)
    logs = tmp_path / "logs"
    with CompanionProcess(sitl.url(0), "--mission", str(mission), "--arm", "--no-zenoh",
                          "--json", "--log-dir", str(logs), "--log-format", "mcap") as comp:
        assert comp.wait(120.0) == 0, comp.stderr
    tlog, = logs.glob("*.tlog")
    live, = logs.glob("*.mcap")
    out = tmp_path / "sitl.mcap"
    p = companion("log", "export", str(tlog), "--mcap", str(out))
    assert p.returncode == 0, p.stderr
    frames, bad = read_tlog(tlog)
    in_tlog = Counter(m.get_type() for _, m in frames)
    counts, _ = _counts(out)
    in_mcap = {t.split("/", 2)[2]: n for t, n in counts.items() if t.startswith("/mavlink/")}
    assert in_mcap == dict(in_tlog) and bad == 0
    live_counts, _ = _counts(live)
    assert live_counts["/rover/loop"] > 100
    print(f"\nArduPilot SITL flight: {len(frames)} tlog messages of {len(in_tlog)} types, all "
          f"in the MCAP: {dict(sorted(in_tlog.items()))}; live MCAP {dict(live_counts)}")
