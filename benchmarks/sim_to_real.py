"""Sim-to-real: the same companion, gains and mission on the bundled plant and on ArduPilot SITL.

For each gains file and each speed of the paper's ellipse, ``companion demo`` flies it against
``sitl-plant --vehicle FILE`` (the identified model, lockstep: seconds) and, with ``--sitl``,
``companion run`` flies it against ArduPilot Rover SITL (``rover-skid``; one instance booted for
every run, extra parameters with ``--param NAME=VALUE``). With ``--native`` ArduPilot's own
GUIDED position-target following (:func:`testbed.baselines.follow`) flies each speed too. It
prints, per row, the steady RMS over the last 30 s on each side, the share of that time the
yaw-rate setpoint sat at its limit (a limit cycle) and whether plant and vehicle agree (within
25 % or 0.05 m).

    python benchmarks/sim_to_real.py --vehicle V.toml --gains A.toml --gains B.toml \\
        --f-r 0.04,0.08 --sitl [--native] [--speedup 1] [--json]

Needs ``ARDUPILOT_SITL`` (or ``ARDUPILOT_DIR``) for ``--sitl``; prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

from testbed.missions import PAPER_ELLIPSES
from testbed.process import companion_json
from testbed.scoring import at_limit_share


def limit_flags(vehicle) -> list[str]:
    out = []
    if math.isfinite(vehicle.max_speed):
        out += ["--max-speed", repr(float(vehicle.max_speed))]
    if math.isfinite(vehicle.max_yaw_rate):
        out += ["--max-yaw-rate", repr(float(vehicle.max_yaw_rate))]
    return out


def on_plant(vehicle_path: str, gains: str, f_r: float, logs: Path, limits: list[str]) -> dict:
    r = companion_json(["demo", "--vehicle", vehicle_path, "--mission",
                        str(PAPER_ELLIPSES[f_r]), "--gains", gains, *limits,
                        "--d-cen", "0", "--json", "--no-plot", "--no-zenoh", "--log-dir",
                        str(logs), "-q"], timeout=300)
    return r


def on_sitl(url: str, gains: str, f_r: float, logs: Path, limits: list[str]) -> dict:
    return companion_json(["run", "--connect", url, "--mission", str(PAPER_ELLIPSES[f_r]),
                           "--gains", gains, *limits, "--arm", "--json", "--no-zenoh",
                           "--log-dir", str(logs), "-q"], timeout=400)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--vehicle", required=True, help="the identified vehicle file")
    p.add_argument("--gains", action="append", required=True, help="a gains file (repeatable)")
    p.add_argument("--f-r", default="0.04,0.08", help="ellipse speeds (0.04, 0.08, 0.12)")
    p.add_argument("--sitl", action="store_true", help="also fly ArduPilot SITL rover-skid")
    p.add_argument("--native", action="store_true", help="and ArduPilot's own following")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="extra ArduPilot parameter for the SITL vehicle (repeatable)")
    p.add_argument("--speedup", type=float, default=1.0, help="SITL speedup (default 1)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()

    from companion.sim import vehicle_file
    vehicle = vehicle_file.load(args.vehicle).params
    limits = limit_flags(vehicle)
    yaw_limit = float(vehicle.max_yaw_rate)
    speeds = [float(v) for v in args.f_r.split(",")]
    params = {k: float(v) for k, v in (item.split("=", 1) for item in args.param)}
    rows = []
    with tempfile.TemporaryDirectory(prefix="sim2real-") as tmp:
        tmp = Path(tmp)
        sitl = None
        if args.sitl:
            from testbed.ardupilot import ArduPilotSITL
            sitl = ArduPilotSITL(tmp / "sitl", speedup=args.speedup, params=params).start()
        try:
            for gains in args.gains:
                for f_r in speeds:
                    row = {"gains": gains, "f_r": f_r}
                    plant = on_plant(args.vehicle, gains, f_r, tmp / "plant", limits)
                    row["plant_rms"] = plant["steady_rms"]
                    row["plant_at_limit"] = at_limit_share(plant["csv"], yaw_limit)
                    if sitl is not None:
                        real = on_sitl(sitl.url(0), gains, f_r, tmp / "sitl_logs", limits)
                        row["sitl_rms"] = real["steady_rms"]
                        row["sitl_at_limit"] = at_limit_share(real["csv"], yaw_limit)
                        a, b = row["plant_rms"], row["sitl_rms"]
                        row["agree"] = abs(a - b) <= max(0.25 * b, 0.05)
                    rows.append(row)
                    print(json.dumps(row), file=sys.stderr, flush=True)
            if args.native and sitl is not None:
                from companion import mission as missions
                from testbed.baselines import follow
                for f_r in speeds:
                    r = follow(sitl.url(0), missions.paper_ellipse(f_r, 60.0), arm=True)
                    rows.append({"gains": "ArduPilot GUIDED position targets", "f_r": f_r,
                                 "sitl_rms": r["steady_rms"]})
        finally:
            if sitl is not None:
                sitl.stop()
    if args.json:
        print(json.dumps({"vehicle": args.vehicle, "params": params, "rows": rows}))
        return 0
    print(f"vehicle model {args.vehicle}; SITL rover-skid {params or 'stock'}")
    print(f"{'gains':40s} {'f_r':>5s} {'plant m':>8s} {'SITL m':>8s} {'limit%':>13s}  agree")
    for r in rows:
        lim = (f"{100 * r.get('plant_at_limit', math.nan):5.1f}/"
               f"{100 * r.get('sitl_at_limit', math.nan):5.1f}")
        print(f"{Path(r['gains']).name[:40]:40s} {r['f_r']:5.2f} {r.get('plant_rms', math.nan):8.3f} "
              f"{r.get('sitl_rms', math.nan):8.3f} {lim:>13s}  {r.get('agree', '')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
