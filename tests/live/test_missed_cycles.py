"""Missed cycles on an uneven but complete stream: ArduPilot at 40 Hz on its 50 Hz scheduler sends
LOCAL_POSITION_NED 20, 20, 20, 40 ms apart, and none of that is a lost sample; a sample that
really is lost (or refused) still counts. The count itself (``TrackingStats``), a model of
ArduPilot's scheduler with the millisecond slips seen on SITL, and the whole companion against a
scripted vehicle sending the pattern over UDP. No SITL needed."""

from __future__ import annotations

import random
from collections import Counter
from itertools import pairwise

import pytest

from companion.live.stats import TrackingStats
from sitl_plant.testing import free_udp_port
from testbed.fake_vehicle import FakeVehicle
from testbed.missions import ellipse_mission
from testbed.process import Companion

PERIOD = 0.025
PATTERN_MS = (20, 20, 20, 40)


def pattern_ms(n: int, phase: int = 0, start: int = 46_031) -> list[int]:
    """n sample times (ms) 20, 20, 20, 40 apart, starting at ``phase`` in the pattern."""
    out, t = [start], start
    for k in range(n - 1):
        t += PATTERN_MS[(phase + k) % 4]
        out.append(t)
    return out


def ardupilot_ms(n: int, seed: int, rate_hz: float = 40.0, loop_hz: float = 50.0,
                 slip: float = 0.02) -> list[int]:
    """ArduPilot's deferred-message scheduling (GCS_Common): a message due every 1/rate_hz goes
    out at the first scheduler tick at or after its due time; ticks are 1/loop_hz apart in whole
    milliseconds, a fraction ``slip`` of them a millisecond early or late (as on SITL)."""
    rng = random.Random(seed)
    tick_ms, interval = round(1000.0 / loop_hz), 1000.0 / rate_hz
    tick = 46_000
    due = tick + rng.uniform(0.0, tick_ms)        # any phase between dues and ticks
    out: list[int] = []
    while len(out) < n:
        if tick >= due:
            out.append(tick)
            due += interval
        tick += tick_ms + (rng.choice((-1, 1)) if rng.random() < slip else 0)
    return out


def feed(times_ms: list[int], period: float = PERIOD) -> tuple[TrackingStats, list[int]]:
    """All samples through one tracking segment; the gap count after each sample."""
    st = TrackingStats(duration=1e9, period=period)
    t0, after = times_ms[0], []
    for ms in times_ms:
        t = ms / 1000.0
        st.add(t - t0 / 1000.0, t, 0.0, 1e-4, backlog=False)
        after.append(st.gaps)
    return st, after


def drop(times: list[int], indices: list[int]) -> list[int]:
    gone = set(indices)
    return [t for i, t in enumerate(times) if i not in gone]


@pytest.mark.parametrize("phase", range(4))
def test_the_20_20_20_40_pattern_is_not_missed_cycles_at_any_phase(phase):
    st, after = feed(pattern_ms(2400, phase))       # 60 s at 40 Hz
    assert max(after) == 0 and st.gaps == 0
    assert st.loop_rate_hz == pytest.approx(40.0, rel=0.002)


def test_scheduler_model_gives_what_sitl_showed():
    times = ardupilot_ms(2400, seed=3)
    intervals = Counter(b - a for a, b in pairwise(times))
    assert intervals[20] + intervals[40] > 0.97 * 2399
    assert set(intervals) <= {19, 20, 21, 39, 40, 41}
    assert (times[-1] - times[0]) / 2399 == pytest.approx(25.0, abs=0.02)


@pytest.mark.parametrize("seed", range(8))
def test_ardupilot_stream_with_tick_slips_counts_nothing(seed):
    st, after = feed(ardupilot_ms(2400, seed))
    assert max(after) == 0, after.index(max(after))


@pytest.mark.parametrize("seed", range(8))
def test_lost_samples_in_the_pattern_are_each_counted_within_a_cycle(seed):
    times = ardupilot_ms(2400, seed)
    rng = random.Random(100 + seed)
    lost = sorted(rng.sample(range(8, 2390), 6)) + [1200, 1201, 1202]   # and three in a row
    lost = sorted(set(lost))
    st, after = feed(drop(times, lost))
    assert st.gaps == len(lost)
    assert after == sorted(after)                  # a count never goes back
    # the k-th loss is counted at the latest four received samples after it
    for k, i in enumerate(lost):
        received_before = i - k                    # samples received before the lost one
        assert after[min(received_before + 3, len(after) - 1)] >= k + 1, (k, i)


def test_exact_pattern_with_a_loss_in_a_20_and_in_a_40_slot():
    times = pattern_ms(400)
    # index 101 sits between two 20 ms intervals, index 104 ends the 40 ms one
    st, after = feed(drop(times, [101, 104, 250]))
    assert st.gaps == 3
    st, _ = feed(drop(times, [2]))                   # in the first cycle of the segment
    assert st.gaps == 1


def test_even_stream_counts_skipped_periods_and_pauses_count_nothing():
    times = [46_000 + 25 * k for k in range(200)]
    st, _ = feed(drop(times, [10, 50, 51, 52, 120]))
    assert st.gaps == 5
    st.segment_start()                             # paused: ten seconds later, nothing missed
    st.add(0.0, times[-1] / 1000.0 + 10.0, 0.0, 1e-4, backlog=False)
    st.add(0.0, times[-1] / 1000.0 + 10.025, 0.0, 1e-4, backlog=False)
    assert st.gaps == 5
    st.lost(0.6)                                   # a gap that resets the tracker: 23 missing
    assert st.gaps == 5 + 23


def test_overruns_still_count_and_unknown_period_counts_nothing():
    st = TrackingStats(duration=10.0, period=PERIOD)
    st.add(0.0, 1.0, 0.0, 0.030, backlog=False)    # answered after more than a period
    st.add(0.025, 1.025, 0.0, 1e-4, backlog=False)
    assert st.overruns == 1 and st.gaps == 0
    st, _ = feed(drop(pattern_ms(100), [50]), period=None)
    assert st.gaps == 0 and st.overruns == 0


@pytest.mark.solo   # judged against the wall clock: alone, after the parallel run
def test_companion_run_counts_no_missed_cycles_on_the_pattern_and_each_refused_sample(tmp_path):
    """The companion as a process against a scripted vehicle over UDP that time-stamps its
    samples 20, 20, 20, 40 ms apart; four samples (and their ATTITUDEs) come from another system id:
    refused, so missed."""
    refused = {150, 151, 203, 260}
    start = 100_000

    def script(k: int, ms: int) -> dict:
        tick = {"ms": start + 100 * (k // 4) + (0, 20, 40, 60)[k % 4]}
        if k in refused:
            tick["sysid"] = 7
        return tick

    mission = ellipse_mission(tmp_path / "m.toml", 8.0)
    port = free_udp_port()
    with Companion(port, "--arm", "--no-zenoh", "--no-log", "--json", "--mission",
                   str(mission)) as comp, FakeVehicle(port, script=script):
        code = comp.wait(60.0)
        r = comp.result()
    assert code == 0, comp.stderr
    assert r["reason"] == "mission_done" and r["telemetry_rejected"]["other_source"] == 8
    assert r["cycles"] >= 8.0 * 40 - 5 and r["loop_rate_hz"] == pytest.approx(40.0, rel=0.02)
    assert r["missed_gaps"] == len(refused), r
    assert r["missed_cycles"] == r["missed_gaps"] + r["overruns"]
