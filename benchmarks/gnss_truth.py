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

The truth is SIM_STATE on the injector's link, matched to a flight's samples by wall time
(the arrival of each LOCAL_POSITION_NED in the companion's .tlog, or in the baseline's trace).

    python -m benchmarks.gnss_truth [--scenario none,rtk-fixed,rtk-float,multipath,plain-gps]
        [--seed 1] [--f-r 0.04] [--model rover-skid] [--vehicle FILE] [--no-native] [--json]

Needs ``ARDUPILOT_SITL`` (or ``ARDUPILOT_DIR``); about 4 minutes a scenario; prints figures,
asserts nothing.
"""

from __future__ import annotations

import argparse
import bisect
import csv
import json
import math
import sys
import tempfile
import threading
from pathlib import Path

from shapely import LineString, Point

from testbed.gnss import SCENARIOS, Scenario
from testbed.gnss_input import GnssInjector, sitl_params
from testbed.missions import PAPER_ELLIPSES, wait_ready
from testbed.process import ROOT, companion_json
from testbed.safety import read_tlog

VEHICLES = {"rover-skid": ROOT / "companion" / "sim" / "vehicles" / "ardupilot_skid.toml"}
STEADY_S = 30.0
AFTER_S = 5.0


class Truth:
    """The injector's truth (wall s, north, east), interpolated at a wall time."""

    def __init__(self, samples: list[tuple[float, float, float]]):
        self.walls = [w for w, _, _ in samples]
        self.samples = samples

    def at(self, wall: float) -> tuple[float, float] | None:
        i = bisect.bisect_right(self.walls, wall)
        if i == 0 or i == len(self.walls):
            return None
        (w0, n0, e0), (w1, n1, e1) = self.samples[i - 1], self.samples[i]
        a = (wall - w0) / (w1 - w0) if w1 > w0 else 0.0
        return n0 + a * (n1 - n0), e0 + a * (e1 - e0)


def companion_trace(result: dict) -> list[tuple[float, float, float, float, float, float]]:
    """(wall, mission s, reference x, y, estimate x, y) of each tracked cycle of a companion
    run: its CSV's rows, timed by the arrival of their LOCAL_POSITION_NED in its .tlog."""
    frames, _ = read_tlog(Path(result["tlog"]))
    arrival = {}
    for wall, m in frames:
        if m.get_type() == "LOCAL_POSITION_NED" and m.get_srcComponent() == 1:
            arrival.setdefault(m.time_boot_ms, wall)
    out = []
    with open(result["csv"], newline="") as f:
        for row in csv.DictReader(f):
            if not row["mission_time"] or not row["x_ref"]:
                continue
            wall = arrival.get(round(float(row["vehicle_time"]) * 1000))
            if wall is not None:
                out.append((wall, float(row["mission_time"]), float(row["x_ref"]),
                            float(row["y_ref"]), float(row["x"]), float(row["y"])))
    return out


def score(trace, truth: Truth, scenario: Scenario, duration: float, t0_wall: float) -> dict:
    """The figures of one flight (module docstring). ``t0_wall``: when the scenario's fixes
    began (its windows are timed from there)."""
    rows = [(r, truth.at(r[0])) for r in trace]
    rows = [(r, p) for r, p in rows if p is not None]
    if not rows:
        return {"error": "no truth matched the flight's samples"}
    (_, _, _, _, ex0, ey0), (tn0, te0) = rows[0]
    path = LineString([(r[2], r[3]) for r, _ in rows])    # where the reference went
    truth_err, est_err, floor, by_wall, by_mt = [], [], [], [], []
    for (wall, mt, xr, yr, xe, ye), (tn, te) in rows:
        xt, yt = tn - tn0 + ex0, te - te0 + ey0          # the truth in the estimate's frame
        e_truth = math.hypot(xr - xt, yr - yt)
        by_wall.append((wall - t0_wall, e_truth, path.distance(Point(xt, yt))))
        by_mt.append((e_truth, mt))
        if mt >= duration - STEADY_S:
            truth_err.append(e_truth)
            est_err.append(math.hypot(xr - xe, yr - ye))
            floor.append(math.hypot(xe - xt, ye - yt))

    def rms(v: list[float]) -> float:
        return math.sqrt(sum(x * x for x in v) / len(v)) if v else math.nan
    faults = []
    for w in scenario.windows:
        inside = [(e, d) for t, e, d in by_wall if w.start <= t < w.start + w.duration]
        end = w.start + w.duration
        after = [e for t, e, _ in by_wall if end + AFTER_S <= t < end + AFTER_S + 0.5]
        faults.append({"start": w.start, "worst": max((e for e, _ in inside), default=math.nan),
                       "from_path": max((d for _, d in inside), default=math.nan),
                       "after": max(after, default=math.nan)})
    return {"truth": rms(truth_err), "estimate": rms(est_err), "floor": rms(floor),
            "worst": max(by_mt), "faults": faults, "samples": len(rows)}


def fly_scenario(scenario: Scenario, seed: int, f_r: float, model: str, vehicle: Path,
                 native: bool, work: Path) -> dict:
    from companion import mission as missions
    from testbed.ardupilot import ArduPilotSITL
    from testbed.baselines import follow

    out: dict = {"scenario": scenario.name, "seed": seed}
    sitl = ArduPilotSITL(work / "sitl", speedup=1.0, params=sitl_params(scenario),
                         model=model).start()
    try:
        url = sitl.url(0)
        ready: dict = {}
        waiter = threading.Thread(target=lambda: ready.update(s=wait_ready(url, work / "logs")),
                                  daemon=True)
        waiter.start()                    # SITL opens SERIAL2 once SERIAL0 has a client
        sitl.wait_log("SERIAL2 on TCP port", 60)
        with GnssInjector(sitl.url(2), scenario, seed) as inj:
            waiter.join(400)
            if "s" not in ready:
                raise SystemExit(f"{scenario.name}: the vehicle never became ready")
            mission = PAPER_ELLIPSES[f_r]
            began = inj.begin()           # the windows, timed from the launch of the run
            r = companion_json(["run", "--connect", url, "--vehicle", str(vehicle), "--mission",
                                str(mission), "--arm", "--json", "--no-zenoh", "--log-dir",
                                str(work / "logs")], timeout=600)
            trace = companion_trace(r)
            duration = float(missions.load(str(mission)).duration)
            out["companion"] = score(trace, Truth(list(inj.truth)), scenario, duration, began)
            out["companion"]["reason"] = r["reason"]
            if native:
                native_trace: list = []
                began = inj.begin()
                follow(url, missions.paper_ellipse(f_r, duration), arm=True, trace=native_trace)
                out["ardupilot"] = score(native_trace, Truth(list(inj.truth)), scenario,
                                         duration, began)
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
                                     work))
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps(rows))
        return 0
    print(f"ArduPilot SITL {args.model}, the paper's ellipse at {args.f_r:g} Hz, seed "
          f"{args.seed}; steady RMS over the last {STEADY_S:g} s, m")
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
