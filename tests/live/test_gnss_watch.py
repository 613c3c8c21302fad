"""The receiver's class as the loop reads it (companion.live.gnss_watch.GnssWatch): the run's
class from its engagement on, the policy's verdict, and how long the run's class has been back."""

from __future__ import annotations

from companion.live.gnss_watch import GnssWatch
from companion.profiles.gnss import CONTINUE, HOLD, GnssPolicy

FLOAT, FIXED = 5, 6


def test_a_drop_from_the_runs_class_holds_until_it_has_been_back_for_back_for():
    w = GnssWatch(GnssPolicy(back_for=2.0))
    assert w.report(FIXED, 14, 0.0) is None
    said = w.begin()
    assert "RTK fixed" in said and w.start_fix == FIXED
    assert w.verdict(0.1) == (CONTINUE, "")
    news = w.report(FLOAT, 400, 1.0)
    assert news == "GNSS RTK fixed -> RTK float (claims 0.40 m)"
    act, why = w.verdict(1.0)
    assert act == HOLD and why == "GNSS RTK float (claims 0.40 m), below the run's RTK fixed"
    assert not w.back(1.5)
    w.report(FIXED, 14, 3.0)
    assert w.verdict(3.0)[0] == CONTINUE and not w.back(4.9) and w.back(5.0)
    w.report(FLOAT, 400, 5.5)                 # again: the count starts afresh
    w.report(FIXED, 14, 6.0)
    assert not w.back(7.9) and w.back(8.0)


def test_the_runs_class_is_the_first_heard_when_it_began_unheard():
    w = GnssWatch(GnssPolicy())
    assert "unknown" in w.begin() and w.start_fix is None
    assert w.verdict(0.0) == (CONTINUE, "") and w.back(0.0)
    w.report(FLOAT, 0, 1.0)
    assert w.start_fix == FLOAT and w.h_acc is None and "claims no accuracy" in w.expectation
    w.report(FIXED, 10, 2.0)
    assert w.verdict(2.0)[0] == CONTINUE


def test_a_receiver_not_heard_for_stale_after_is_not_judged():
    w = GnssWatch(GnssPolicy(stale_after=2.0))
    w.report(FIXED, 14, 0.0)
    w.begin()
    w.report(FLOAT, 400, 1.0)
    assert w.verdict(2.9)[0] == HOLD
    assert w.verdict(3.1) == (CONTINUE, "") and w.back(3.1)


def test_status_says_the_class_now_and_the_runs():
    w = GnssWatch(GnssPolicy())
    w.report(FIXED, 14, 0.0)
    w.begin()
    w.report(FLOAT, 400, 1.0)
    w.noted(HOLD, 1.0)
    s = w.status()
    assert s["fix"] == "RTK float" and s["run_fix"] == "RTK fixed" and s["h_acc"] == 0.4
    assert s["drops"] == 1 and w.summary()["drop_log"][0]["action"] == HOLD


def test_a_drop_below_a_dgps_run_slows_the_reference_to_half_and_back(tmp_path):
    """Through a real companion process: a scripted vehicle (testbed.fake_vehicle) reports DGPS,
    then a 3D fix for 2 s of its time, then DGPS again. Mission time runs at half the vehicle's
    clock while the fix is 3D, at full speed before and after; the drop is said and logged."""
    import csv

    from sitl_plant.testing import free_udp_port
    from testbed.fake_vehicle import FakeVehicle
    from testbed.missions import ellipse_mission
    from testbed.process import Companion

    step = 25                                        # ms: 40 Hz ticks
    slow_from, slow_to = 104_000, 106_000            # vehicle ms of the 3D fix

    def script(k: int, ms: int) -> dict:
        tick: dict = {"ms": ms}
        if k % 4 == 0:                               # 10 Hz
            tick["gps"] = (3, 1500) if slow_from <= ms < slow_to else (4, 600)
        return tick

    mission = ellipse_mission(tmp_path / "m.toml", 8.0, f_r=0.05)
    port = free_udp_port()
    with Companion(port, "--arm", "--no-zenoh", "--json", "--log-dir", str(tmp_path),
                   "--mission", str(mission)) as comp, \
            FakeVehicle(port, script=script, start_ms=100_000, step_ms=step):
        code = comp.wait(60.0)
        r = comp.result()
    assert code == 0 and r["reason"] == "mission_done", comp.stderr
    assert "GNSS DGPS (the receiver claims 0.60 m)" in comp.stderr
    assert "GNSS 3D fix (claims 1.50 m), below the run's DGPS: the reference slowed to 50%" \
        in comp.stderr and "the reference at full speed again" in comp.stderr
    assert [d["action"] for d in r["gnss"]["drop_log"]] == ["slow"]
    rows = [(float(x["vehicle_time"]), float(x["mission_time"]))
            for x in csv.DictReader(open(r["csv"], newline="")) if x["mission_time"]]

    def rate(t0: float, t1: float) -> float:
        inside = [(t, m) for t, m in rows if t0 <= t <= t1]
        (ta, ma), (tb, mb) = inside[0], inside[-1]
        return (mb - ma) / (tb - ta)

    assert abs(rate(slow_from / 1e3 + 0.3, slow_to / 1e3 - 0.1) - 0.5) < 0.01
    assert abs(rate(slow_to / 1e3 + 0.3, slow_to / 1e3 + 2.0) - 1.0) < 0.01
