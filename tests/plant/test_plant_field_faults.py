"""The field faults of issue 21 on the bundled plant: ``sitl-plant --gps-glitch`` and
``--gps-loss`` make its EKF report what ArduPilot SITL's does (and, for a glitch, move
LOCAL_POSITION_NED by the glitch), and ``companion run`` pauses at once (zero setpoints,
HOLD), resumes once the estimate has been healthy for --estimate-healthy-for, and finishes;
or ends with exit 6 (--on-bad-estimate end). Real processes over loopback UDP, the plant in
lockstep so the vehicle times below are exact."""

from __future__ import annotations

import pytest

from sitl_plant.testing import PlantProcess
from testbed.fake_vehicle import is_mode_command, is_zero
from testbed.missions import ellipse_mission
from testbed.process import Companion
from testbed.udp_proxy import Proxy

HOLD = 4
FAULT_AT, FAULT_FOR = 6.0, 3.0          # vehicle s (the plant boots at 0, tracking from ~1 s)


def _fly(tmp_path, fault: str, *flags: str):
    mission = ellipse_mission(tmp_path / "m.toml", 12.0, f_r=0.05)
    # The companion first, the plant once it listens: the plant's clock (and so the fault)
    # starts at its boot, and the companion must be tracking by FAULT_AT however long its
    # start-up took on a loaded machine (a fault while it first engages is only waited out).
    with Proxy() as proxy, \
            Companion(proxy.companion_port, "--arm", "--no-zenoh", "--json", "--no-log",
                      "--mission", str(mission), "--estimate-healthy-for", "1", *flags) as comp:
        comp.wait_bound(proxy.companion_port)
        with PlantProcess("--lockstep", fault, f"{FAULT_AT:g},{FAULT_FOR:g}",
                          port=proxy.plant_port):
            code = comp.wait(90.0)
        r = comp.result()
        sent = [s.msg for s in proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")]
        commands = [s.msg for s in proxy.companion_sent("COMMAND_LONG")]
        reports = [s.msg for s in proxy.plant_sent("EKF_STATUS_REPORT")]
    return code, r, comp, sent, commands, reports


@pytest.mark.parametrize("fault, flags, words", [
    ("--gps-glitch", 0x833F, "GPS glitching"),
    ("--gps-loss", 0x27, "no absolute horizontal position"),
])
def test_the_estimate_flagged_pauses_and_the_run_resumes(tmp_path, fault, flags, words):
    code, r, comp, sent, commands, reports = _fly(tmp_path, fault)
    assert code == 0 and r["reason"] == "mission_done", comp.stderr
    line = next(x for x in comp.stderr.splitlines() if "estimate unhealthy" in x)
    assert (f"EKF_STATUS_REPORT flags 0x{flags:x}: " in line and words in line
            or "LOCAL_POSITION_NED stepped 14" in line), line
    assert any(m.flags == flags for m in reports) and reports[-1].flags == 0x33F
    assert r["failsafes"] >= 1 and any(is_mode_command(c, HOLD) for c in commands)
    # nothing but zero setpoints from the fault until it has been over for 1 s
    start, end = int(FAULT_AT * 1000), int((FAULT_AT + FAULT_FOR + 1.0) * 1000)
    during = [m for m in sent if start + 200 <= m.time_boot_ms < end]
    assert during and all(is_zero(m) for m in during), [m.time_boot_ms for m in during
                                                        if not is_zero(m)][:5]
    assert any(not is_zero(m) for m in sent if m.time_boot_ms > end + 500)   # tracking again
    assert r["duration_s"] >= 12.0 - 1e-6


def test_a_glitch_with_on_bad_estimate_end_ends_with_exit_6(tmp_path):
    code, r, comp, sent, commands, reports = _fly(tmp_path, "--gps-glitch",
                                                  "--on-bad-estimate", "end")
    assert code == 6 and r["stop_cause"] == "estimate_unhealthy", comp.stderr
    assert r["reason"].startswith("estimate_unhealthy: "), r
    late = [m for m in sent if m.time_boot_ms >= int(FAULT_AT * 1000)]
    assert late and all(is_zero(m) for m in late)
