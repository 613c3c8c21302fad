"""``companion monitor`` against ``companion demo`` (an operator's tools reaching a demo):
``--once --json`` snapshot and ``--record FILE``."""

from __future__ import annotations

import json

from zenoh_harness import ISOLATED, Proc, endpoint, free_tcp_port


def test_monitor_once_json_and_record_see_a_demo(tmp_path):
    port = free_tcp_port()
    record = tmp_path / "stream.jsonl"
    with Proc("demo", "--speedup", "1", "--duration", "20", "--rate", "20", "--no-plot",
              "--json", "--zenoh-listen", endpoint(port), "--vehicle-id", "demo-1", *ISOLATED,
              tmp=tmp_path, name="demo") as demo:
        demo.wait_line("publishing rover/demo-1/state", 20.0)
        demo.wait_line("armed: tracking", 20.0)
        with Proc("monitor", "--once", "--json", "--wait", "2", "--record", str(record),
                  "--zenoh-connect", endpoint(port), *ISOLATED, tmp=tmp_path,
                  name="monitor") as monitor:
            assert monitor.wait(10.0) == 0, monitor.stderr
        snap = json.loads(monitor.stdout.strip())
        demo.stop()
    assert snap["schema"] == "pzc-rover/monitor/1"
    (v,) = snap["vehicles"]
    assert v["vehicle_id"] == "demo-1" and v["mode"] == "GUIDED" and v["armed"] is True
    assert v["state"] == "tracking" and v["age_s"] < 0.5 and v["lost"] == 0 and v["bad"] == 0
    assert 25 <= v["state_msgs"] <= 45, v          # ~2 s at 20 Hz
    assert 0.0 < v["speed"] < 6.5 and v["err_pos"] is not None
    assert v["max_gap_ms"] < 200.0, v
    lines = [json.loads(line) for line in record.read_text().splitlines()]
    states = [r for r in lines if r["key"] == "rover/demo-1/state"]
    assert len(states) == v["state_msgs"]
    assert all(r["payload"]["schema"] == "pzc-rover/state/1" and r["rx"] >= r["payload"]["sent_at"]
               for r in states)
