"""A fleet on one machine: 10 sitl-plant + companion pairs at 20 Hz in real time, all through
one ``companion router``, and one ``companion monitor`` that must see all 10 vehicles with no gap
in any state stream longer than 200 ms (the issue's criterion)."""

from __future__ import annotations

import pytest

from testbed.zenoh_fleet import run_fleet

N, RATE, DURATION = 10, 20.0, 10.0
MAX_GAP_MS = 200.0


# solo: 22 processes on two cores judged against the wall clock (200 ms); beside the other
# workers' flights the machine itself stalls that long (CI: 182-247 ms, every vehicle alike).
@pytest.mark.slow
@pytest.mark.solo
def test_ten_vehicles_through_one_router_seen_by_one_monitor(tmp_path):
    fleet = run_fleet(N, tmp_path, rate=RATE, duration=DURATION, timeout=150.0)
    ids = {f"rover{i}" for i in range(1, N + 1)}
    seen = {v["vehicle_id"]: v for v in fleet.snapshot["vehicles"]}
    missed = [r and r["missed_cycles"] for r in fleet.results]
    print(f"\nfleet of {N} at {RATE:g} Hz: wall {fleet.wall_s:.1f} s, max gap per vehicle (ms) "
          f"{ {k: round(v) for k, v in sorted(fleet.gaps_ms.items())} }, missed cycles {missed}, "
          f"exit after SIGTERM {fleet.exit_s}")
    assert set(seen) == ids, sorted(seen)
    assert max(fleet.exit_s.values()) <= 2.0, fleet.exit_s      # monitor, router: SIGTERM

    assert fleet.codes == [0] * N, (fleet.codes, fleet.results)
    for r in fleet.results:
        assert r["reason"] == "mission_done" and r["duration_s"] >= DURATION - 0.1, r
    for vid in ids:
        v = seen[vid]
        # Every cycle of the mission arrived (20 Hz x 10 s), none lost, no long silence.
        assert fleet.counts[vid] >= RATE * DURATION - 2, (vid, fleet.counts[vid])
        assert v["lost"] == 0 and v["bad"] == 0, v
        assert v["max_gap_ms"] == pytest.approx(fleet.gaps_ms[vid], abs=1.0)
        assert fleet.gaps_ms[vid] < MAX_GAP_MS, (vid, fleet.gaps_ms)
