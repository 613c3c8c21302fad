"""``companion run`` against the bundled ``sitl-plant``: two OS processes over loopback UDP.

The paper's ellipse (f_r 0.12 Hz) on the paper's plant with d_cen 0.3 m, 40 Hz telemetry.
"""

from __future__ import annotations

import math

import pytest

from sitl_plant.testing import PlantProcess
from testbed.fake_vehicle import is_mode_command, is_zero
from testbed.missions import ellipse_mission
from testbed.process import Companion
from testbed.scoring import batch_twin
from testbed.udp_proxy import Proxy

MISSION = "missions/paper_ellipse_012.toml"


def fly(plant_args, companion_args, timeout=60.0):
    with PlantProcess(*plant_args) as plant, \
            Companion(plant.port, "--arm", "--json", "-q", *companion_args) as comp:
        code = comp.wait(timeout)
        assert code == 0, comp.stderr
        return comp.result()


def test_lockstep_tracks_the_paper_ellipse_and_agrees_with_batch():
    r = fly(["--lockstep", "--d-cen", "0.3"], ["--mission", MISSION])
    assert r["reason"] == "mission_done" and r["hold_confirmed"]
    assert r["rate_accepted_hz"] == 40.0
    assert r["loop_rate_hz"] == pytest.approx(40.0, rel=1e-6)
    assert r["cycles"] == 2400 and r["duration_s"] == pytest.approx(60.0)
    assert r["missed_gaps"] == 0 and sum(r["telemetry_rejected"].values()) == 0
    assert r["steady_rms"] <= 0.3
    twin = batch_twin(r)
    assert r["f_cost"] == pytest.approx(twin, rel=0.05), (r["f_cost"], twin)


@pytest.mark.solo   # judged against the wall clock: alone, after the parallel run
def test_speedup_tracks_the_paper_ellipse():
    """Paced at 5 x real time: the loop runs on the vehicle's clock, so it still tracks."""
    r = fly(["--speedup", "5", "--d-cen", "0.3"], ["--mission", MISSION], timeout=60.0)
    assert r["reason"] == "mission_done"
    assert r["loop_rate_hz"] == pytest.approx(40.0, rel=0.02)
    # Paced runs depend on getting the CPU in time: say how the loop fared if this fails.
    health = {k: r.get(k) for k in ("failsafes", "missed_cycles", "overruns", "latency_max_ms",
                                    "telemetry_rejected", "f_cost")}
    assert r["steady_rms"] <= 0.3, health
    # The lockstep test holds the batch twin to 5 %; paced, a stall of either process on a busy
    # machine lands setpoints late in the transient (f_cost 4.19 against 3.81 was seen with a
    # PX4 SITL running beside the suite on 2 cores), while the steady state above still holds.
    assert r["f_cost"] == pytest.approx(batch_twin(r), rel=0.20), health


def test_refused_rate_falls_back_to_one_the_vehicle_accepts(tmp_path):
    """The plant (like ArduPilot at SCHED_LOOP_RATE 50) refuses 100 Hz; 40 Hz is accepted."""
    mission = ellipse_mission(tmp_path / "m.toml", 5.0)
    r = fly(["--lockstep", "--d-cen", "0.3"], ["--mission", str(mission), "--rate", "100"])
    assert r["rate_requested_hz"] == 100.0 and r["rate_accepted_hz"] == 40.0
    assert r["loop_rate_hz"] == pytest.approx(40.0, rel=1e-6)


def test_px4_gets_velocity_vectors_in_offboard(tmp_path):
    mission = ellipse_mission(tmp_path / "m.toml", 5.0)
    with Proxy() as proxy, \
            PlantProcess("--lockstep", "--autopilot", "px4", "--d-cen", "0.3",
                         port=proxy.plant_port), \
            Companion(proxy.companion_port, "--arm", "--json", "-q", "--mission",
                      str(mission)) as comp:
        assert comp.wait(60.0) == 0, comp.stderr
        r = comp.result()
    assert r["autopilot"] == "px4" and r["reason"] == "mission_done" and r["hold_confirmed"]
    sps = [s.msg for s in proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")]
    assert {(sp.coordinate_frame, sp.type_mask) for sp in sps} == {(1, 3559)}
    moving = [sp for sp in sps if not is_zero(sp)]
    assert len(moving) >= 150 and all(sp.yaw_rate == 0.0 for sp in sps)
    modes = [s.msg for s in proxy.companion_sent("COMMAND_LONG") if s.msg.command == 176]
    assert int(modes[0].param2) == 6                       # OFFBOARD (main mode 6)
    assert (int(modes[-1].param2), int(modes[-1].param3)) == (4, 3)   # Hold = AUTO_LOITER


def test_ardupilot_setpoints_are_body_speed_and_yaw_rate(tmp_path):
    mission = ellipse_mission(tmp_path / "m.toml", 3.0)
    with Proxy() as proxy, \
            PlantProcess("--lockstep", "--d-cen", "0.3", port=proxy.plant_port), \
            Companion(proxy.companion_port, "--arm", "--json", "-q", "--mission", str(mission),
                      "--max-speed", "2", "--max-yaw-rate", "1.5") as comp:
        assert comp.wait(60.0) == 0, comp.stderr
    sps = [s.msg for s in proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")]
    assert {(sp.coordinate_frame, sp.type_mask) for sp in sps} == {(8, 1511)}
    assert all(sp.vy == 0.0 and abs(sp.vx) <= 2.0 and abs(sp.yaw_rate) <= 1.5 for sp in sps)
    assert max(abs(sp.vx) for sp in sps) == pytest.approx(2.0)   # the limit is reached, not passed
    # every setpoint answers one LOCAL_POSITION_NED: its time_boot_ms is that sample's
    tel = {s.msg.time_boot_ms for s in proxy.plant_sent("LOCAL_POSITION_NED")}
    assert {sp.time_boot_ms for sp in sps if sp.time_boot_ms} <= tel
    assert is_zero(sps[-1])
    assert is_mode_command(proxy.companion_sent("COMMAND_LONG")[-1].msg, 4)
    assert not any(math.isnan(sp.vx) for sp in sps)


def test_realtime_flag_takes_sched_fifo_or_says_why_not(tmp_path):
    mission = ellipse_mission(tmp_path / "m.toml", 3.0)
    with PlantProcess("--lockstep") as plant, \
            Companion(plant.port, "--arm", "--json", "--realtime", "--mission", str(mission)) as comp:
        assert comp.wait(60.0) == 0, comp.stderr
        result = comp.result()
    assert result["reason"] == "mission_done"
    assert ("control loop under SCHED_FIFO" in comp.stderr
            or "SCHED_FIFO not granted" in comp.stderr), comp.stderr
