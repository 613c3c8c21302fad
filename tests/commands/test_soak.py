"""Soak: 10 minutes of vehicle time in lockstep on a link with 1 % telemetry dropout, duplicates,
reordering and bursts. Tracking stays good, no setpoint is invalid (checked from the flight
log, which holds every one sent), and the companion's memory stays flat. Real processes over
loopback UDP."""

from __future__ import annotations

import math
import time

import pytest

from sitl_plant.testing import PlantProcess
from testbed.process import Companion
from testbed.safety import read_tlog, rss_kb

MINUTES = 10
MAX_SPEED, MAX_YAW_RATE = 6.0, 6.0


@pytest.mark.slow   # long: started first under workers (conftest.py)
def test_ten_minutes_of_faulty_link_in_lockstep(tmp_path):
    mission = tmp_path / "m.toml"
    mission.write_text(f'name = "soak"\nframe = "start"\nduration = {MINUTES * 60}\n'
                       '[trajectory]\nkind = "ellipse"\nf_r = 0.12\n')
    rss: list[tuple[float, int]] = []
    t0 = time.monotonic()
    with PlantProcess("--lockstep", "--lockstep-timeout", "0.02", "--d-cen", "0.3",
                      "--dropout", "0.01", "--duplicate", "0.01", "--reorder", "0.01",
                      "--burst", "0.002", "--seed", "11") as plant, \
            Companion(plant.port, "--arm", "--no-zenoh", "--json", "-q", "--mission", str(mission),
                      "--log-dir", str(tmp_path)) as comp:
        while comp.proc.poll() is None and time.monotonic() - t0 < 170:
            try:
                rss.append((time.monotonic() - t0, rss_kb(comp.proc.pid)))
            except OSError:
                break
            time.sleep(0.5)
        assert comp.wait(30.0) == 0, comp.stderr
        r = comp.result()
        plant.stop()
    wall = time.monotonic() - t0
    summary = plant.stderr.strip().splitlines()[-1]
    rej = r["telemetry_rejected"]

    # every setpoint the companion sent, read back from its .tlog
    frames, bad = read_tlog(next(tmp_path.glob("*.tlog")))
    sps = [m for _, m in frames if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
    invalid = [m for m in sps if not (all(math.isfinite(v) for v in (m.vx, m.vy, m.yaw_rate))
                                      and abs(m.vx) <= MAX_SPEED
                                      and abs(m.yaw_rate) <= MAX_YAW_RATE)]
    # memory: from the end of the first fifth (imports, buffers, histogram warm) to the end
    steady = [kb for t, kb in rss if t >= 0.2 * rss[-1][0]]
    growth_kb = steady[-1] - steady[0]
    print(f"\nsoak: {r['duration_s']:.0f} s of vehicle time in {wall:.1f} s wall; steady RMS "
          f"{r['steady_rms']:.4f} m, f_cost {r['f_cost']:.3f}; {r['cycles']} cycles, "
          f"{len(sps)} setpoints ({len(invalid)} invalid), refused {rej}, "
          f"tracker resets {r['tracker_resets']}, failsafes {r['failsafes']}; companion RSS "
          f"{steady[0] / 1024:.1f} -> {steady[-1] / 1024:.1f} MiB (growth {growth_kb} kB, "
          f"max {max(kb for _, kb in rss) / 1024:.1f} MiB, {len(rss)} samples); plant: {summary}")
    assert r["reason"] == "mission_done" and r["duration_s"] >= MINUTES * 60 - 1e-6
    assert r["steady_rms"] <= 0.5
    assert bad == 0 and len(sps) == r["setpoints_sent"] and invalid == []
    # the faults really happened, and were refused rather than used
    assert "0 handler errors" in summary
    for word in ("dropped", "duplicated", "reordered", "bursts"):
        n = int(summary.split(f" {word}")[0].split()[-1])
        assert n >= 20, (word, summary)
    assert rej["duplicate"] >= 100 and rej["time_backwards"] >= 100
    assert len(steady) >= 10 and growth_kb <= 8 * 1024
