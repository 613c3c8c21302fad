"""The receiver's class on the bundled plant (issue 44): ``sitl-plant --gps-float`` reports RTK
float in GPS_RAW_INT and moves LOCAL_POSITION_NED with its EKF unflagged, as ArduPilot's does;
``companion run`` says what to expect of the run's RTK fixed before the rover moves, holds on
the path at the first float report (zero setpoints, HOLD, the mission clock held), and rejoins
the path where it stopped once fixed has been back for the profile's ``back_for``, skipping
nothing. Real processes over loopback UDP, the plant in lockstep (exact vehicle times)."""

from __future__ import annotations

import csv
import math

from companion.profiles.gnss import GnssPolicy
from sitl_plant.status import GpsFault, position_offset
from sitl_plant.testing import PlantProcess
from testbed.fake_vehicle import is_mode_command, is_zero
from testbed.missions import ellipse_mission
from testbed.process import Companion
from testbed.udp_proxy import Proxy

HOLD = 4
FLOAT_AT, FLOAT_FOR = 6.0, 3.0          # vehicle s (the plant boots at 0, tracking from ~1 s)
BACK_FOR = GnssPolicy().back_for


def test_rtk_float_holds_on_the_path_and_the_run_resumes_where_it_stopped(tmp_path):
    mission = ellipse_mission(tmp_path / "m.toml", 12.0, f_r=0.05)
    with Proxy() as proxy, \
            Companion(proxy.companion_port, "--arm", "--no-zenoh", "--json", "--no-log",
                      "--mission", str(mission)) as comp:
        comp.wait_bound(proxy.companion_port)
        with PlantProcess("--lockstep", "--gps-float", f"{FLOAT_AT:g},{FLOAT_FOR:g}",
                          port=proxy.plant_port):
            code = comp.wait(90.0)
        r = comp.result()
        sent = [s.msg for s in proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")]
        commands = [s.msg for s in proxy.companion_sent("COMMAND_LONG")]
        texts = [s.msg.text for s in proxy.companion_sent("STATUSTEXT")]
    assert code == 0 and r["reason"] == "mission_done", comp.stderr
    lines = comp.stderr.splitlines()
    said = next(i for i, x in enumerate(lines) if "GNSS RTK fixed (the receiver claims 0.01 m)"
                in x)
    assert said < next(i for i, x in enumerate(lines) if "tracking 'm'" in x or
                       ": tracking" in x), lines
    hold = next(x for x in lines if "estimate" not in x and "holding on the path" in x)
    assert "GNSS RTK float (claims 0.40 m), below the run's RTK fixed" in hold, hold
    assert any("FAILSAFE: GNSS RTK float" in t for t in texts), texts
    assert any(is_mode_command(c, HOLD) for c in commands)
    # nothing but zero setpoints from the first float report until fixed has been back for
    # back_for (the estimate is 0.3 m off meanwhile, and the rover does not chase it)
    start, end = int(FLOAT_AT * 1000) + 200, int((FLOAT_AT + FLOAT_FOR + BACK_FOR) * 1000)
    during = [m for m in sent if start <= m.time_boot_ms < end]
    assert during and all(is_zero(m) for m in during), [m.time_boot_ms for m in during
                                                        if not is_zero(m)][:5]
    assert any(not is_zero(m) for m in sent if m.time_boot_ms > end + 1500)   # tracking again
    assert r["duration_s"] >= 12.0 - 1e-6                      # nothing of the mission skipped
    g = r["gnss"]
    assert g["run_fix"] == "RTK fixed" and g["fix"] == "RTK fixed", g
    assert [d["action"] for d in g["drop_log"]] == ["hold"] and g["drop_log"][0]["fix"] == \
        "RTK float", g
    assert "GNSS back to the run's RTK fixed" in comp.stderr


JUMP_AT, JUMP_FOR, JUMP = 6.0, 3.0, 0.25


def test_a_jump_of_a_fixed_receiver_is_ridden_through_not_followed(tmp_path):
    """``--gps-jump``: GPS_RAW_INT moves 0.25 m north at once, still "fixed"; the plant's
    LOCAL_POSITION_NED slides after it. The companion steers by the rover's own motion meanwhile:
    the plant's truth (its estimate less the offset it added) stays on the reference while the
    estimate is a quarter of a metre off it, and the estimate is handed back once it returns."""
    mission = ellipse_mission(tmp_path / "m.toml", 14.0, f_r=0.05)
    with Proxy() as proxy, \
            Companion(proxy.companion_port, "--arm", "--no-zenoh", "--json", "--log-dir",
                      str(tmp_path), "--mission", str(mission)) as comp:
        comp.wait_bound(proxy.companion_port)
        with PlantProcess("--lockstep", "--gps-jump", f"{JUMP_AT:g},{JUMP_FOR:g}",
                          port=proxy.plant_port):
            code = comp.wait(90.0)
        r = comp.result()
    assert code == 0 and r["reason"] == "mission_done" and r["failsafes"] == 0, comp.stderr
    assert "riding through on the receiver less the jump" in comp.stderr
    assert "the receiver is back" in comp.stderr
    faults = (GpsFault("jump", JUMP_AT, JUMP_FOR, JUMP),)
    rows = [row for row in csv.DictReader(open(r["csv"], newline="")) if row["x_ref"]]
    truth_err, estimate_err = [], []
    for row in rows:
        t = float(row["vehicle_time"])
        if JUMP_AT <= t < JUMP_AT + JUMP_FOR + 3.0:
            x_true = float(row["x"]) - position_offset(t, faults)
            truth_err.append(math.hypot(float(row["x_ref"]) - x_true,
                                        float(row["y_ref"]) - float(row["y"])))
            estimate_err.append(float(row["err_pos"]))
    assert max(estimate_err) > 0.15                  # the estimate did move a quarter metre
    assert max(truth_err) < 0.05, max(truth_err)     # the rover did not
