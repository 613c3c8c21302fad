"""``companion monitor`` against ``companion demo`` (an operator's tools reaching a demo):
``--once --json`` snapshot and ``--record FILE``."""

from __future__ import annotations

import json

from testbed.zenoh_fleet import ISOLATED, Proc, endpoint, free_tcp_port


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


class _Sample:
    """What the monitor reads of a Zenoh sample: its key expression and payload bytes."""

    def __init__(self, key: str, payload: dict):
        from companion.bus.codec import encode
        self.key_expr, self._data = key, encode(payload)
        self.payload = self

    def to_bytes(self) -> bytes:
        return self._data


def test_the_last_snapshot_and_the_record_count_the_same_messages(tmp_path):
    """Zenoh's threads can deliver a sample after ``--once``'s snapshot and before the session
    closes (a fresh-clone CI run recorded 40 states against a snapshot of 39): the last snapshot
    ends counting and recording together."""
    from companion.commands.monitor import Fleet

    def state(seq: int) -> _Sample:
        return _Sample("rover/r1/state", {"schema": "pzc-rover/state/1", "vehicle_id": "r1",
                                          "seq": seq, "every": 1, "mode": "GUIDED", "armed": True})

    path = tmp_path / "rec.jsonl"
    with open(path, "w", encoding="utf-8") as record:
        fleet = Fleet(record)
        for seq in range(3):
            fleet.on_sample(state(seq))
        assert fleet.snapshot()["vehicles"][0]["state_msgs"] == 3
        fleet.on_sample(state(3))                     # a snapshot while running does not freeze
        snap = fleet.snapshot(last=True)
        fleet.on_sample(state(4))                     # arrives between the snapshot and close
    (v,) = snap["vehicles"]
    assert v["state_msgs"] == 4 and v["lost"] == 0
    seqs = [json.loads(line)["payload"]["seq"] for line in path.read_text().splitlines()]
    assert seqs == [0, 1, 2, 3]
    assert fleet.snapshot()["vehicles"][0]["state_msgs"] == 4
