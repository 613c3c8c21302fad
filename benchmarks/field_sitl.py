"""A field flown on ArduPilot SITL, scored from the simulator's truth (issue 45), beside
ArduPilot's own AUTO on the same swaths.

The field is missions/field.toml's (20 m x 12 m, 1 m swaths along it, a 3 m headland), placed
in the local frame so its route starts where the rover boots. A fresh ``ardurover`` (speedup 1)
takes exact fixes from the injector (scenario ``none`` of :mod:`testbed.gnss`: the truth from
``SIM_STATE``, 120 ms lag, no error), so the truth is known and the estimate is good. On it:

1. ``companion run`` flies the field (``--vehicle FILE``);
2. ArduPilot's AUTO flies the swaths' end points uploaded as waypoints (what a user does
   without the companion), at ``WP_SPEED`` = the field's straight speed.

Each is scored from the truth over its flight (:mod:`companion.mission.coverage`, as a run's
JSON scores its estimate): cross-track on the swath interiors (p50, p95, max; the mean to the
right of the swaths driven out and back), the farthest excursion beyond the boundary, the share
of the swath area missed by a tool of the spacing + 0.1 m, and the wall time.

    python -m benchmarks.field_sitl [--model rover-skid] [--vehicle FILE] [--no-native]
        [--turn-rate 0.5] [--json]

Needs ``ARDUPILOT_SITL``; about 8 minutes; prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from companion.mission.coverage import figures
from testbed.gnss import SCENARIOS
from testbed.gnss_flight import gnss_vehicle, truth_between
from testbed.gnss_input import sitl_params
from testbed.missions import FIELD_SPACING as SPACING
from testbed.missions import FIELD_SPEED as SPEED
from testbed.missions import field_mission
from testbed.process import ROOT, companion_json

VEHICLES = {"rover-skid": ROOT / "companion" / "sim" / "vehicles" / "ardupilot_skid.toml"}


def fly_auto(url: str, swaths, speed: float, timeout: float = 900.0) -> tuple[float, float]:
    """ArduPilot's AUTO along the swaths' end points: (start, end) of the field on the
    truth's clock (time.time()), from reaching the first swath's start to the last end."""
    from testbed.mission_gcs import GroundStation, waypoint_mission
    with GroundStation(url) as gcs:
        asked = time.monotonic()
        gcs.command((1, 1), 512, 49)          # MAV_CMD_REQUEST_MESSAGE: GPS_GLOBAL_ORIGIN
        origin = gcs.wait_for(lambda: gcs.of("GPS_GLOBAL_ORIGIN", (1, 1), asked), 10.0,
                              "the EKF origin")[-1]
        home = (origin.latitude / 1e7, origin.longitude / 1e7)
        items = waypoint_mission(home, [p for swath in swaths for p in swath], speed)
        gcs.upload(1, items)
        gcs.mav.param_set_send(1, 1, b"WP_SPEED", speed, 9)
        deadline = time.monotonic() + 120
        while gcs.command((1, 1), 400, 1) != 0:                # arm
            if time.monotonic() > deadline:
                raise RuntimeError("AUTO: never armed")
            time.sleep(1)
        began = time.monotonic()
        while gcs.command((1, 1), 176, 1, 10) != 0:            # AUTO
            time.sleep(0.5)

        def reached(seq: int) -> float:
            return gcs.wait_for(lambda: [h.wall for h in gcs.heard
                                         if h.wall >= began and h.msg.get_type() ==
                                         "MISSION_ITEM_REACHED" and h.msg.seq == seq],
                                timeout, f"AUTO reaching item {seq}")[0]
        t0 = reached(2)                     # the first swath's start: the field begins
        t1 = reached(len(items) - 1)
        to_wall = time.time() - time.monotonic()     # the truth is stamped by time.time()
        gcs.command((1, 1), 176, 1, 4)                          # HOLD
        gcs.command((1, 1), 400, 0)
    return t0 + to_wall, t1 + to_wall


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default="rover-skid")
    p.add_argument("--vehicle", type=Path)
    p.add_argument("--turn-rate", type=float, default=0.5)
    p.add_argument("--no-native", action="store_true", help="skip ArduPilot's own AUTO")
    p.add_argument("--keep", metavar="DIR")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    vehicle = args.vehicle or VEHICLES.get(args.model)
    if vehicle is None:
        p.error(f"--model {args.model}: no bundled vehicle file; give --vehicle")
    from companion import mission as missions
    from testbed.ardupilot import ArduPilotSITL
    scenario = SCENARIOS["none"]
    rows = {}
    with tempfile.TemporaryDirectory(prefix="field-sitl-") as tmp:
        work = Path(args.keep or tmp)
        work.mkdir(parents=True, exist_ok=True)
        mission = field_mission(work / "field.toml", args.turn_rate)
        m = missions.load(mission)
        cover = m.trajectory.cover
        tool = SPACING + 0.1
        sitl = ArduPilotSITL(work / "sitl", speedup=1.0, params=sitl_params(scenario),
                             model=args.model).start()
        try:
            url = sitl.url(0)
            with gnss_vehicle(sitl, scenario, 1, work / "logs") as inj:
                t0 = time.time()
                r = companion_json(["run", "--connect", url, "--vehicle", str(vehicle),
                                    "--mission", str(mission), "--arm", "--json", "--no-zenoh",
                                    "--log-dir", str(work / "logs")], timeout=900)
                t1 = time.time()
                rows["companion"] = figures(truth_between(inj, t0, t1), cover, tool)
                rows["companion"].update(reason=r["reason"], wall_s=t1 - t0)
                print(json.dumps(rows), file=sys.stderr, flush=True)
                if not args.no_native:
                    a0, a1 = fly_auto(url, cover.swaths, SPEED)
                    rows["ardupilot_auto"] = figures(truth_between(inj, a0, a1), cover, tool)
                    rows["ardupilot_auto"].update(wall_s=a1 - a0)
        finally:
            sitl.stop()
    if args.json:
        print(json.dumps(rows))
        return 0
    print(f"ArduPilot SITL {args.model}, missions/field.toml's field (20 x 12 m, 1 m swaths, "
          f"3 m headland) at {SPEED:g} m/s, turns at {args.turn_rate:g} rad/s; from the truth")
    print(f"{'':16s} {'p50':>6s} {'p95':>6s} {'max':>6s} {'excursion':>9s} {'missed':>7s} "
          f"{'wall s':>7s}")
    for name, f in rows.items():
        print(f"{name:16s} {f['cross_track_p50']:6.3f} {f['cross_track_p95']:6.3f} "
              f"{f['cross_track_max']:6.3f} {f['excursion']:9.3f} {100 * f['missed']:6.2f}% "
              f"{f['wall_s']:7.1f}   mean to the right, swaths out / back: "
              + " / ".join(f"{b:+.3f}" for b in f["lean_out_back"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
