"""Tracking against the simulator's truth under a field's GNSS (issue 44), ArduPilot SITL.

For each scenario of :data:`testbed.gnss.SCENARIOS` a fresh ``ardurover`` (speedup 1,
``GPS1_TYPE 14``) takes its fixes from the injector (:mod:`testbed.gnss_input`: the truth from
``SIM_STATE`` plus the seeded receiver error, on SERIAL2). On it, the paper's ellipse is flown
by ``companion run --vehicle FILE`` and then by ArduPilot's own GUIDED following
(:func:`testbed.baselines.follow`), and each is scored from the truth:

* ``truth``: steady RMS over the last 30 s of the true position against the reference that
  flight flew (the companion's own, from its CSV; the baseline's, from its trace);
* ``estimate``: the same against LOCAL_POSITION_NED (what every figure before issue 44 used);
* ``floor``: the estimate's RMS error against the truth over the same 30 s, both taken relative
  to where they were when tracking began (the anchoring of the reference), what no tracker fed
  the estimate can beat;
* ``worst in fault``: the largest truth error inside each of the scenario's windows (against
  the reference point; a held reference leaves the braking distance in it), ``from path``: the
  largest distance of the truth from the path itself (shapely) there, and
  ``after``: the largest over half a second, 5 s after each (has it settled?).

The truth is SIM_STATE on the injector's link, matched to a flight's samples on the vehicle's
clock (each sample's LOCAL_POSITION_NED ``time_boot_ms``; the truth's from the same message on
the injector's link); the JSON's ``by_wall`` has the older match by wall time (the arrival of
each sample) beside it.

    python -m benchmarks.gnss_truth [--scenario none,rtk-fixed,rtk-float,multipath,plain-gps]
        [--seed 1] [--f-r 0.04] [--model rover-skid] [--vehicle FILE] [--no-native] [--json]
        [--companion-args "--lambda-f 5"]

Needs ``ARDUPILOT_SITL`` (or ``ARDUPILOT_DIR``); about 4 minutes a scenario; prints figures,
asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
import tempfile
from pathlib import Path

from testbed.gnss import SCENARIOS, Scenario
from testbed.gnss_flight import STEADY_S, Truth, companion_trace, gnss_vehicle, score
from testbed.gnss_input import sitl_params
from testbed.missions import PAPER_ELLIPSES
from testbed.process import ROOT, companion_json

VEHICLES = {"rover-skid": ROOT / "companion" / "sim" / "vehicles" / "ardupilot_skid.toml"}


def fly_scenario(scenario: Scenario, seed: int, f_r: float, model: str, vehicle: Path,
                 native: bool, work: Path, extra: list[str] | None = None) -> dict:
    from companion import mission as missions
    from testbed.ardupilot import ArduPilotSITL
    from testbed.baselines import follow

    out: dict = {"scenario": scenario.name, "seed": seed}
    sitl = ArduPilotSITL(work / "sitl", speedup=1.0, params=sitl_params(scenario),
                         model=model).start()
    try:
        url = sitl.url(0)
        with gnss_vehicle(sitl, scenario, seed, work / "logs") as inj:
            mission = PAPER_ELLIPSES[f_r]
            began = inj.begin()           # the windows, timed from the launch of the run
            r = companion_json(["run", "--connect", url, "--vehicle", str(vehicle), "--mission",
                                str(mission), "--arm", "--json", "--no-zenoh", "--log-dir",
                                str(work / "logs"), *(extra or [])], timeout=600)
            trace = companion_trace(r)
            duration = float(missions.load(str(mission)).duration)
            truth = Truth(list(inj.truth), list(inj.clock))
            out["companion"] = score(trace, truth, scenario, duration, began)
            # the older match, by wall time, beside it (what it adds: docs/gnss.md)
            by_wall = score(trace, Truth(list(inj.truth)), scenario, duration, began)
            out["companion"]["by_wall"] = {k: by_wall.get(k) for k in ("truth", "floor")}
            out["companion"]["reason"] = r["reason"]
            if native:
                native_trace: list = []
                began = inj.begin()
                follow(url, missions.paper_ellipse(f_r, duration), arm=True, trace=native_trace)
                out["ardupilot"] = score(native_trace, Truth(list(inj.truth), list(inj.clock)),
                                         scenario, duration, began)
    finally:
        sitl.stop()
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default=",".join(SCENARIOS))
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--f-r", type=float, default=0.04, choices=sorted(PAPER_ELLIPSES))
    p.add_argument("--model", default="rover-skid",
                   help="SITL frame: rover-skid (default) or rover (Ackermann; give --vehicle)")
    p.add_argument("--vehicle", type=Path, help="the calibrated vehicle file (default: the "
                   "bundled one for rover-skid)")
    p.add_argument("--no-native", action="store_true", help="skip ArduPilot's own following")
    p.add_argument("--companion-args", default="", metavar="ARGS",
                   help='more for `companion run`, e.g. "--lambda-f 5" (the filter sweep)')
    p.add_argument("--keep", metavar="DIR", help="keep the logs here")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    if args.vehicle is None and args.model not in VEHICLES:
        p.error(f"--model {args.model}: no bundled vehicle file; give --vehicle (from "
                "companion calibrate)")
    names = args.scenario.split(",")
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        p.error(f"--scenario: unknown {', '.join(unknown)} (known: {', '.join(SCENARIOS)})")
    rows = []
    with tempfile.TemporaryDirectory(prefix="gnss-truth-") as tmp:
        for name in names:
            work = Path(args.keep or tmp) / name
            work.mkdir(parents=True, exist_ok=True)
            rows.append(fly_scenario(SCENARIOS[name], args.seed, args.f_r, args.model,
                                     args.vehicle or VEHICLES[args.model], not args.no_native,
                                     work, shlex.split(args.companion_args)))
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps(rows))
        return 0
    print(f"ArduPilot SITL {args.model}, the paper's ellipse at {args.f_r:g} Hz, seed "
          f"{args.seed}{'; companion run ' + args.companion_args if args.companion_args else ''}"
          f"; steady RMS over the last {STEADY_S:g} s, m")
    print(f"{'scenario':12s} {'truth':>7s} {'estimate':>8s} {'floor':>7s} {'worst in fault':>15s} "
          f"{'from path':>15s} {'after':>15s} {'ArduPilot':>9s}")
    for row in rows:
        c, a = row["companion"], row.get("ardupilot", {})
        worst = ",".join(f"{f['worst']:.2f}" for f in c["faults"]) or "-"
        after = ",".join(f"{f['after']:.2f}" for f in c["faults"]) or "-"
        path = ",".join(f"{f['from_path']:.2f}" for f in c["faults"]) or "-"
        print(f"{row['scenario']:12s} {c['truth']:7.3f} {c['estimate']:8.3f} {c['floor']:7.3f} "
              f"{worst:>15s} {path:>15s} {after:>15s} {a.get('truth', math.nan):9.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
