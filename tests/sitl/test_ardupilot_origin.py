"""Missions placed by latitude / longitude fly where they were drawn, on ArduPilot Rover SITL
booted away from the plan's home (``--home`` 50 m north of it).

The EKF origin (what LOCAL_POSITION_NED is relative to) is where the vehicle got its first GPS
fix, not the plan's home: the companion must read it from the vehicle (GPS_GLOBAL_ORIGIN) and
place the plan around it. Checked from the vehicle's own GLOBAL_POSITION_INT, recorded by a
ground station on SERIAL0 (which also boots SITL and drives the rover about); the companion
runs as a process on SERIAL1. Skipped unless ARDUPILOT_SITL or ARDUPILOT_DIR is set.
"""

from __future__ import annotations

import time

import pytest

from testbed.ardupilot import GUIDED, HOLD, CompanionProcess, GroundStation
from testbed.origin import (
    CMAC,
    closest_approaches,
    metres_between,
    moved,
    path_distances,
    plan_waypoints,
    write_plan,
)
from testbed.process import ROOT

SPEEDUP = 5
BOOT_WALL = 120.0 / SPEEDUP + 20.0     # wall s: boot to armable, with margin
BOOT = moved(CMAC, 50.0, 0.0)          # where SITL boots: 50 m north of the plan's home
GLOBAL_POSITION_INT = 33
POSITION_ONLY = 0b0000_1111_1111_1000  # SET_POSITION_TARGET_GLOBAL_INT: use lat, lon, alt
FRAME_GLOBAL_INT = 5
VEHICLE = str(ROOT / "companion" / "sim" / "vehicles" / "ardupilot_skid.toml")


def _arm_in_guided(gs: GroundStation) -> None:
    deadline = time.monotonic() + BOOT_WALL
    assert gs.set_mode(GUIDED) == 0
    while gs.command(400, 1.0) != 0:           # refused until the EKF uses GPS (~40 s)
        assert time.monotonic() < deadline, "SITL would not arm"
        time.sleep(0.5)


def _drive_to(gs: GroundStation, target: tuple[float, float], timeout: float = 60.0) -> float:
    """ArduPilot's own GUIDED navigation to ``target``, then HOLD; the distance it stopped at."""
    deadline = time.monotonic() + timeout
    next_send = 0.0
    while True:
        now = time.monotonic()
        assert now < deadline, f"the rover did not reach {target}"
        if now >= next_send:
            with gs._lock:
                gs.mav.set_position_target_global_int_send(
                    0, 1, 1, FRAME_GLOBAL_INT, POSITION_ONLY, int(round(target[0] * 1e7)),
                    int(round(target[1] * 1e7)), 584.0, 0, 0, 0, 0, 0, 0, 0, 0)
            next_send = now + 1.0
        fixes = gs.messages("GLOBAL_POSITION_INT", after=now - 0.5)
        if fixes:
            last = fixes[-1]
            away = metres_between((last.lat * 1e-7, last.lon * 1e-7), target)
            if away < 2.5 and abs(last.vx) + abs(last.vy) < 10:    # cm/s
                assert gs.set_mode(HOLD) == 0
                return away
        time.sleep(0.1)


def _companion(sitl, plan, *extra: str) -> CompanionProcess:
    # the identified SITL rover-skid: its limits and the gains tuned for it (shipped beside it)
    return CompanionProcess(sitl.url(1), "--mission", str(plan), "--arm", "--no-zenoh",
                            "--json", "--vehicle", VEHICLE, *extra)


@pytest.mark.sitl
@pytest.mark.slow
@pytest.mark.parametrize("which", ["gentle", "example_rover"])
def test_a_plan_flies_where_drawn_on_ardupilot_booted_50_m_away(ardupilot, tmp_path, capsys,
                                                                 which):
    """``gentle``: a plan written here, bends of 20-30 degrees: every waypoint within 1 m.
    ``example_rover``: the shipped plan (the issue's), whose corners the path rounds with 2 m
    arcs (0.83 m inside its 90 degree corner by design): every waypoint within 1 m, or 0.5 m
    of where the path itself passes it (0.3 m was missed by 0.02 m once with the machine's two
    cores loaded: the rover cutting the rounded corner a little more)."""
    if which == "gentle":
        plan = tmp_path / "gentle.plan"
        waypoints = write_plan(plan, CMAC)
    else:
        plan = ROOT / "missions" / "example_rover.plan"
        waypoints = plan_waypoints(plan)
    by_design = path_distances(plan, waypoints)
    # WP_RADIUS 0.5: the ground station's drive to the plan's home stops nearer it
    sitl = ardupilot(speedup=SPEEDUP, home=(*BOOT, 584.0, 180.0), params={"WP_RADIUS": 0.5})
    with GroundStation(sitl, serial=0) as gs:
        sitl.wait_log("SERIAL1 on TCP port", 15.0)
        assert gs.set_rate(GLOBAL_POSITION_INT, 20.0) == 0

        # The case: the rover where it booted, the plan's start 50 m away. The origin
        # is waited for (not set yet at boot), then the run is refused before anything moves.
        with _companion(sitl, plan, "--no-log") as comp:
            code = comp.wait(BOOT_WALL + 30.0)
        errors = [line for line in comp.stderr.splitlines() if "error" in line]
        assert code == 2, comp.stderr
        assert len(errors) == 1 and "starts 5" in errors[0] and "--max-start-distance 25" in errors[0]
        assert "Traceback" not in comp.stderr
        assert "EKF origin" in comp.stderr                     # it did learn the origin first
        refusal = errors[0]

        # Drive the rover to the plan's start (as a user would), then fly the plan.
        _arm_in_guided(gs)
        stopped_at = _drive_to(gs, CMAC)
        t0 = time.monotonic()
        with _companion(sitl, plan, "--log-dir", str(tmp_path / "logs")) as comp:
            code = comp.wait(120.0)
        r = comp.result()
        assert code == 0 and r["reason"] == "mission_done", comp.stderr
        origin = (r["ekf_origin"]["lat"], r["ekf_origin"]["lon"])
        assert r["ekf_origin"]["source"] == "GPS_GLOBAL_ORIGIN"
        assert metres_between(origin, BOOT) < 1.0              # where it booted, not the plan's home
        fixes = gs.messages("GLOBAL_POSITION_INT", after=t0)
        approaches = closest_approaches(fixes, waypoints)
        with capsys.disabled():
            print(f"\n{which}: refused where it booted: {refusal}")
            print(f"{which}: stopped {stopped_at:.2f} m from the plan's home; EKF origin "
                  f"{metres_between(origin, BOOT):.2f} m from --home; steady RMS "
                  f"{r['steady_rms']:.3f} m; closest approach per waypoint (m): "
                  + ", ".join(f"{a:.2f}" for a in approaches) + "; the path's own: "
                  + ", ".join(f"{d:.2f}" for d in by_design))
        for got, path in zip(approaches, by_design, strict=True):
            assert got < max(1.0, path + 0.5), (approaches, by_design)
        if which == "gentle":
            assert max(approaches) < 1.0
