"""The whole flow on ArduPilot Rover SITL, against ArduPilot's own following, in one session.

Boots ``ardurover`` (``--model``: ``rover-skid`` by default, ``rover`` for ArduPilot's
Ackermann car on rover.parm alone; ``--param NAME=VALUE`` for another vehicle), then

0. a one-second stand-still ``companion run`` that waits for the fresh SITL's GPS and EKF
   (:func:`testbed.missions.wait_ready`), so calibrate's clock starts on a booted vehicle;
1. ``companion calibrate --connect ... --out DIR --arm``: identify live, tune;
2. ``companion run --vehicle DIR/vehicle.toml`` on the paper's ellipse at each ``--f-r``;
3. ArduPilot's GUIDED position-target following (:func:`testbed.baselines.follow`) on the same ellipses,

and prints, per speed, the steady RMS over the last 30 s of each and the share of that time the
companion's yaw-rate setpoint sat at its limit (a limit cycle shows as a large share).

    python benchmarks/sitl_tracking.py [--model rover] [--param ATC_ACCEL_MAX=0.5 ...] [--speedup 3] [--json]

Needs ``ARDUPILOT_SITL`` (or ``ARDUPILOT_DIR``); prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

from testbed.missions import PAPER_ELLIPSES, wait_ready
from testbed.process import companion_json
from testbed.scoring import at_limit_share


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="an ArduPilot parameter for this vehicle (repeatable)")
    p.add_argument("--model", default="rover-skid",
                   help="SITL frame: rover-skid (default) or rover (Ackermann, rover.parm only)")
    p.add_argument("--f-r", default="0.04,0.08,0.12")
    p.add_argument("--speedup", type=float, default=1.0, help="SITL speedup (default 1)")
    p.add_argument("--keep", metavar="DIR", help="keep vehicle.toml, gains.toml and logs here")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    from companion import mission as missions
    from testbed.ardupilot import ArduPilotSITL
    from testbed.baselines import follow

    params = {k: float(v) for k, v in (item.split("=", 1) for item in args.param)}
    speeds = [float(v) for v in args.f_r.split(",")]
    rows, out = [], {}
    with tempfile.TemporaryDirectory(prefix="sitl-tracking-") as tmp:
        work = Path(args.keep) if args.keep else Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        sitl = ArduPilotSITL(Path(tmp) / "sitl", speedup=args.speedup, params=params,
                             model=args.model).start()
        try:
            url = sitl.url(0)
            out["boot_s"] = wait_ready(url, work / "logs")   # not calibrate's time
            t0 = time.monotonic()
            cal = companion_json(["calibrate", "--connect", url, "--out", str(work / "rover"),
                             "--arm", "--no-zenoh", "--log-dir", str(work / "logs"), "--json"],
                            timeout=1800)   # a loaded machine: calibrate took 575 s once
            out["calibrate_wall_s"] = time.monotonic() - t0
            out["vehicle"] = cal["vehicle"]
            ident = cal["identify"]
            out["identified"] = ident["params"]
            out["identify_rms"] = ident["rms"]
            out["timings_s"], out["cpu_s"] = cal.get("timings_s"), cal.get("cpu_s")
            out["refine"] = {k: v for k, v in cal.get("refine", {}).items() if k != "tlog"}
            vehicle = cal["vehicle"]
            from companion.sim import vehicle_file
            yaw_limit = float(vehicle_file.load(vehicle).params.max_yaw_rate)
            for f_r in speeds:
                r = companion_json(["run", "--connect", url, "--vehicle", vehicle, "--mission",
                               str(PAPER_ELLIPSES[f_r]), "--arm", "--json",
                               "--no-zenoh", "--log-dir", str(work / "logs")], timeout=600)
                rows.append({"f_r": f_r, "companion_rms": r["steady_rms"],
                             "at_limit": at_limit_share(r["csv"], yaw_limit),
                             "gains": r["gains_source"]})
                print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
            for row in rows:
                native = follow(url, missions.paper_ellipse(row["f_r"], 60.0), arm=True)
                row["ardupilot_rms"] = native["steady_rms"]
                print(json.dumps(row), file=sys.stderr, flush=True)
        finally:
            sitl.stop()
    out["params"], out["rows"], out["model"] = params, rows, args.model
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"ArduPilot SITL {args.model} {params or 'stock'}: calibrate {out['calibrate_wall_s']:.0f} s "
          f"wall; identified accel {out['identified']['speed']['accel_max_m_s2']:.3g} m/s^2, "
          f"turn-rate accel {out['identified']['turn_rate']['accel_max_rad_s2']:.3g} rad/s^2")
    print(f"{'f_r':>5s} {'companion m':>12s} {'at limit %':>11s} {'ArduPilot m':>12s}")
    for r in rows:
        print(f"{r['f_r']:5.2f} {r['companion_rms']:12.3f} {100 * r['at_limit']:11.1f} "
              f"{r.get('ardupilot_rms', math.nan):12.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
