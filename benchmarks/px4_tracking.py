"""The companion against PX4's own following on PX4 SITL (SIH Ackermann rover), in one session.

For each ``--f-r`` of the paper's ellipse (60 s, anchored at the rover's start), on a fresh PX4
process each (``testbed/px4.py``; PX4 runs in real time, so each flight costs its 60 s):

1. PX4's OFFBOARD position following (:func:`testbed.baselines.follow`: position + velocity
   setpoints);
2. ``companion run`` with the shipped default gains, or ``--vehicle FILE`` (a ``companion
   calibrate`` result), or ``--calibrate`` (calibrate on a fresh PX4 first, then fly its file).

Prints, per speed, the steady RMS over the last 30 s of each and, for the companion, the largest
lead of the rover's heading over the reference's course (degrees, unwrapped: 360 or more is a
loop the rover drove that the reference did not).

    python benchmarks/px4_tracking.py [--f-r 0.04,0.08] [--vehicle DIR/vehicle.toml | --calibrate]
                                      [--keep DIR] [--json]

Needs ``PX4_SITL`` (or ``PX4_DIR``); prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys
import tempfile
import time
from itertools import pairwise
from pathlib import Path

from testbed.process import companion_json


def heading_lead_deg(csv_path: str) -> float:
    """The largest |unwrapped heading - unwrapped reference course| over the mission, in
    degrees (the start's difference, within +-180, included)."""
    with open(csv_path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["mission_time"]]
    lead_max, prev_yaw, prev_ref = 0.0, None, None
    unwrapped_yaw = unwrapped_ref = 0.0
    for a, b in pairwise(rows):
        dx, dy = float(b["x_ref"]) - float(a["x_ref"]), float(b["y_ref"]) - float(a["y_ref"])
        if math.hypot(dx, dy) < 1e-6:
            continue
        ref, yaw = math.atan2(dy, dx), float(b["yaw"])
        if prev_yaw is None:
            unwrapped_yaw = yaw
            unwrapped_ref = yaw - math.remainder(yaw - ref, 2 * math.pi)
        else:
            unwrapped_yaw += math.remainder(yaw - prev_yaw, 2 * math.pi)
            unwrapped_ref += math.remainder(ref - prev_ref, 2 * math.pi)
        prev_yaw, prev_ref = yaw, ref
        lead_max = max(lead_max, abs(unwrapped_yaw - unwrapped_ref))
    return math.degrees(lead_max)


def ellipse_mission(path: Path, f_r: float, duration: float) -> Path:
    path.write_text(f'name = "paper ellipse {f_r:g} Hz"\nframe = "start"\nduration = {duration:g}\n'
                    f'[trajectory]\nkind = "ellipse"\nf_r = {f_r:g}\n')
    return path


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--f-r", default="0.04,0.08")
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--vehicle", help="fly the companion with this vehicle file")
    p.add_argument("--calibrate", action="store_true",
                   help="companion calibrate on a fresh PX4 first, then fly its vehicle file")
    p.add_argument("--no-native", action="store_true", help="skip PX4's own following")
    p.add_argument("--extra", default="", help="more arguments for companion run (one string)")
    p.add_argument("--keep", metavar="DIR", help="keep logs and calibration here")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    if not (os.environ.get("PX4_SITL") or os.environ.get("PX4_DIR")):
        raise SystemExit("px4_tracking: set PX4_SITL (the px4 binary) or PX4_DIR")
    from companion import mission as missions
    from testbed.baselines import follow
    from testbed.px4 import PX4SITL

    speeds = [float(v) for v in args.f_r.split(",")]
    rows, out = [], {"duration": args.duration}
    with tempfile.TemporaryDirectory(prefix="px4-tracking-") as tmp:
        work = Path(args.keep) if args.keep else Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        vehicle = args.vehicle
        if args.calibrate:
            with PX4SITL(Path(tmp) / "px4-cal") as sitl:
                t0 = time.monotonic()
                cal = companion_json(["calibrate", "--connect", sitl.url(), "--out",
                                 str(work / "rover"), "--arm", "--no-zenoh", "--log-dir",
                                 str(work / "logs"), "--json"], timeout=1200)
                out["calibrate_wall_s"] = time.monotonic() - t0
            vehicle = cal["vehicle"]
            out["calibrate"] = {k: cal[k] for k in ("vehicle", "identify", "refine",
                                                    "timings_s", "cpu_s") if k in cal}
        for f_r in speeds:
            row: dict = {"f_r": f_r}
            mission = ellipse_mission(work / f"ellipse_{f_r:g}.toml", f_r, args.duration)
            if not args.no_native:
                with PX4SITL(Path(tmp) / f"px4-native-{f_r:g}") as sitl:
                    native = follow(sitl.url(), missions.paper_ellipse(f_r, args.duration),
                                    arm=True)
                row["px4_rms"] = native["steady_rms"]
            with PX4SITL(Path(tmp) / f"px4-companion-{f_r:g}") as sitl:
                argv = ["run", "--connect", sitl.url(), "--mission", str(mission), "--arm",
                        "--json", "--no-zenoh", "--log-dir", str(work / "logs"),
                        *(["--vehicle", vehicle] if vehicle else []), *args.extra.split()]
                r = companion_json(argv, timeout=args.duration + 180)
            row.update(companion_rms=r["steady_rms"], heading_lead_deg=heading_lead_deg(r["csv"]),
                       gains=r["gains_source"], csv=r["csv"])
            rows.append(row)
            print(json.dumps(row), file=sys.stderr, flush=True)
    out["rows"] = rows
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"PX4 SITL SIH Ackermann rover, paper's ellipse {args.duration:g} s, steady RMS over the "
          f"last {args.duration / 2:g} s; companion gains: {rows[0]['gains'] if rows else '-'}")
    print(f"{'f_r':>5s} {'PX4 own m':>10s} {'companion m':>12s} {'heading lead deg':>17s}")
    for r in rows:
        print(f"{r['f_r']:5.2f} {r.get('px4_rms', math.nan):10.3f} {r['companion_rms']:12.3f} "
              f"{r['heading_lead_deg']:17.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
