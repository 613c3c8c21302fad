"""The vehicle matrix: calibrate + run on ArduPilot Rover SITL over vehicles tuned differently.

For every configuration (a SITL frame and the inner-loop parameters a builder changes), one
fresh ``ardurover`` is booted and

1. ``companion calibrate --connect ... --out DIR --arm`` identifies it live and tunes for it
   (its wall time and its own per-step timings are kept);
2. ``companion run --vehicle DIR/vehicle.toml`` flies the paper's ellipse (60 s, 40 Hz, anchored
   at the start pose) at each ``--f-r``;
3. ``companion run --controller kanayama --controller-gains ... --vehicle DIR/vehicle.toml``
   flies the same, the classical law live within the same vehicle's limits, with the gains
   picked by hand for the frame (``benchmarks/kanayama_gains.toml``, ``[skid]`` or
   ``[ackermann]``: not its defaults, which limit-cycle on these rovers);
4. ArduPilot's own GUIDED position-target following (:func:`testbed.baselines.follow`) flies
   the same.

Scored from the vehicle's own LOCAL_POSITION_NED: the steady RMS of |p_ref - p| over the last
30 s. Rows are written one JSON file per configuration into ``--out`` as they finish (several
invocations may share the folder, e.g. one per configuration, run side by side), and the table
is printed from every row in the folder (``--table``: print only).

    python benchmarks/vehicle_matrix.py --out /tmp/matrix [--configs stock,accel ...]
        [--frame skid|ackermann] [--f-r 0.04,0.08] [--repeat N]
    python benchmarks/vehicle_matrix.py --out /tmp/matrix --table

``--frame ackermann`` boots SITL ``--model rover`` (ArduPilot's default car, ``rover.parm``
only) instead of ``rover-skid``; it needs a vehicle model for Ackermann steering (issue 20,
item 1) to calibrate. ``--repeat N`` calibrates (and flies) each configuration N times on N
fresh SITL boots (item 3's repeatability). Where the vehicle cannot follow the reference the
floor (:mod:`testbed.reach_floor`, the identified top speed) is printed beside it.

Needs ``ARDUPILOT_SITL`` (or ``ARDUPILOT_DIR``); prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from testbed.baselines import kanayama_argv
from testbed.missions import PAPER_ELLIPSES, ready_argv
from testbed.process import ROOT

# name -> the ArduPilot parameters set over the frame's defaults (stock ArduPilot values in
# the comments: ATC_ACCEL_MAX 1 (SITL rover-skid), ATC_DECEL_MAX 0 (= accel), ATC_STR_ACC_MAX
# 120 deg/s^2, ATC_STR_RAT_MAX 120 deg/s, ATC_STR_RAT_FF 0.2, MOT_STR_THR_MIX 0.5,
# CRUISE_SPEED 3 / CRUISE_THROTTLE 75 (rover-skid.parm), WP_SPEED 3)
CONFIGS: dict[str, dict[str, float]] = {
    "stock": {},
    "accel": {"ATC_ACCEL_MAX": 0.5, "ATC_DECEL_MAX": 2.0},
    "steer-slow": {"ATC_STR_ACC_MAX": 60.0, "ATC_STR_RAT_MAX": 60.0},
    "rate-ff": {"ATC_STR_RAT_FF": 0.5},
    "thr-mix": {"MOT_STR_THR_MIX": 1.0},
    "cruise": {"CRUISE_SPEED": 2.0, "CRUISE_THROTTLE": 60.0, "WP_SPEED": 2.0},
    "mixed": {"ATC_ACCEL_MAX": 2.0, "ATC_STR_ACC_MAX": 240.0, "ATC_STR_RAT_FF": 0.1,
              "MOT_STR_THR_MIX": 0.2, "WP_SPEED": 4.0},
}
MODELS = {"skid": "rover-skid", "ackermann": "rover"}     # --frame -> SITL --model


def companion(argv: list[str], timeout: float) -> tuple[dict, float, str]:
    """(its JSON result or {exit_code, reason}, wall s, the tail of stderr)."""
    t0 = time.monotonic()
    try:
        p = subprocess.run([sys.executable, "-m", "companion", *argv], capture_output=True,
                           text=True, timeout=timeout, cwd=ROOT)
    except subprocess.TimeoutExpired:     # (subprocess.run kills it) a row, not a crash
        return ({"exit_code": None, "reason": f"companion {argv[0]}: still running after "
                                              f"{timeout:g} s"}, time.monotonic() - t0, "")
    wall = time.monotonic() - t0
    lines = [ln for ln in p.stdout.strip().splitlines() if ln.startswith("{")]
    try:
        result = json.loads(lines[-1])
    except (IndexError, json.JSONDecodeError):
        result = {"exit_code": p.returncode, "reason": p.stderr.strip()[-400:]}
    return result, wall, p.stderr[-2000:]


def wait_ready(url: str, logs: Path) -> float:
    """The stand-still mission (:func:`testbed.missions.ready_argv`), flown so that calibrate's clock starts on a booted
    vehicle (its result is not checked: a vehicle still not ready fails calibrate, in its own
    row). The wall seconds it took."""
    t0 = time.monotonic()
    companion(ready_argv(url, logs), 300)
    return time.monotonic() - t0


def one(name: str, params: dict[str, float], frame: str, speeds: list[float], work: Path,
        native: bool, kanayama: bool = True) -> dict:
    from companion import mission as missions
    from testbed.ardupilot import ArduPilotSITL
    from testbed.baselines import follow

    logs = work / "logs"
    row: dict = {"config": name, "frame": frame, "params": params, "runs": {}}
    sitl = ArduPilotSITL(work / "sitl", params=params, model=MODELS[frame]).start()
    try:
        url = sitl.url(0)
        row["boot_s"] = wait_ready(url, logs)
        cal, wall, err = companion(["calibrate", "--connect", url, "--out", str(work / "rover"),
                                    "--arm", "--no-zenoh", "--log-dir", str(logs), "--json"],
                                   1800)
        row["calibrate_wall_s"] = wall
        row["calibrate_exit"] = cal.get("exit_code", 0) if "vehicle" not in cal else 0
        if "vehicle" not in cal:
            row["calibrate_error"] = cal.get("reason") or err[-400:]
            return row
        row["timings_s"] = cal.get("timings_s")
        ident = cal["identify"]
        row["identified"] = ident["params"]
        row["identify_rms"] = ident["rms"]
        row["refine"] = {k: v for k, v in cal["refine"].items() if k != "tlog"}
        vehicle = cal["vehicle"]
        for f_r in speeds:
            mission = str(PAPER_ELLIPSES[f_r])
            base = ["run", "--connect", url, "--vehicle", vehicle, "--mission", mission, "--arm",
                    "--json", "--no-zenoh", "--log-dir", str(logs), "-q"]
            flown = [("pzc", [])] + ([("kanayama", kanayama_argv(frame))] if kanayama else [])
            for label, extra in flown:
                r, _, err = companion(base + extra, 600)
                row["runs"][f"{label}@{f_r:g}"] = {
                    "steady_rms": r.get("steady_rms"), "exit_code": r.get("exit_code"),
                    "reason": r.get("reason"), "gains_source": r.get("gains_source")}
                print(f"{name} {label} {f_r:g} Hz: {r.get('steady_rms')}", file=sys.stderr,
                      flush=True)
            if native:
                n = follow(url, missions.paper_ellipse(f_r, 60.0), arm=True)
                row["runs"][f"ardupilot@{f_r:g}"] = {"steady_rms": n["steady_rms"]}
    finally:
        sitl.stop()
    return row


def floor_for(row: dict, f_r: float) -> float | None:
    """The reach floor at ``f_r`` for the identified top speed, or along the reference's path
    with its acceleration and deceleration too (:func:`testbed.reach_floor.path_floor`), the
    larger (None below 1 cm)."""
    try:
        speed = row["identified"]["speed"]
        top = float(speed["max_m_s"])
        accel = float(speed["accel_max_m_s2"])
        decel = float(speed["decel_max_m_s2"] or accel)
    except (KeyError, TypeError, ValueError):
        return None
    from testbed.reach_floor import floor, path_floor
    value, _ = floor(f_r, top, iterations=4000)
    value = max(value, path_floor(f_r, top, accel, decel, iterations=4000)[0])
    return value if value >= 0.01 else None


def fmt(value, spec: str = ".3f") -> str:
    return "n/a" if value is None or not math.isfinite(float(value)) else format(value, spec)


def table(rows: list[dict], speeds: list[float]) -> str:
    head = ["config", "frame", "params", "calibrate s"]
    for f_r in speeds:
        head += [f"pzc {f_r:g}", f"kanayama {f_r:g}", f"ArduPilot {f_r:g}", f"floor {f_r:g}"]
    head += ["accel m/s^2", "turn accel rad/s^2", "fit RMS m/s, rad/s", "refined"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        cells = [row["config"], row["frame"],
                 ", ".join(f"{k}={v:g}" for k, v in row["params"].items()) or "stock",
                 fmt(row.get("calibrate_wall_s"), ".0f")]
        for f_r in speeds:
            runs = row.get("runs", {})
            cells += [fmt((runs.get(f"{c}@{f_r:g}") or {}).get("steady_rms"))
                      for c in ("pzc", "kanayama", "ardupilot")]
            cells.append(fmt(floor_for(row, f_r)) if "identified" in row else "n/a")
        ident = row.get("identified")
        if ident:
            rms = row["identify_rms"]
            cells += [fmt(ident["speed"]["accel_max_m_s2"], ".3g"),
                      fmt(ident["turn_rate"]["accel_max_rad_s2"], ".3g"),
                      f"{rms['speed_m_s']:.3f}, {rms['yaw_rate_rad_s']:.3f}",
                      "yes" if row["refine"].get("refined") else
                      f"no: {row['refine'].get('why')}"]
        else:
            cells += ["calibrate failed: " + str(row.get("calibrate_error", ""))[-120:].replace(
                "\n", " "), "", "", ""]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, metavar="DIR", help="rows (JSON) and logs go here")
    p.add_argument("--configs", default=",".join(CONFIGS), help=", ".join(CONFIGS))
    p.add_argument("--frame", choices=tuple(MODELS), default="skid")
    p.add_argument("--f-r", default="0.04,0.08")
    p.add_argument("--repeat", type=int, default=1, help="calibrations per configuration")
    p.add_argument("--no-native", dest="native", action="store_false",
                   help="skip ArduPilot's own following")
    p.add_argument("--no-kanayama", dest="kanayama", action="store_false",
                   help="skip the Kanayama law flown live")
    p.add_argument("--table", action="store_true", help="only print the table of --out's rows")
    args = p.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    speeds = [float(v) for v in args.f_r.split(",")]
    if not args.table:
        names = args.configs.split(",")
        bad = [n for n in names if n not in CONFIGS] + [f for f in speeds if f not in PAPER_ELLIPSES]
        if bad:
            p.error(f"unknown configuration or speed: {bad}")
        for name in names:
            for k in range(args.repeat):
                label = f"{name}-{args.frame}" + (f"-{k + 1}" if args.repeat > 1 else "")
                work = Path(tempfile.mkdtemp(prefix=f"matrix-{label}-", dir=out))
                row = one(name, CONFIGS[name], args.frame, speeds, work, args.native,
                          args.kanayama)
                row.update(label=label, date=datetime.date.today().isoformat(),
                           command=shlex.join(["python", "benchmarks/vehicle_matrix.py",
                                               *sys.argv[1:]]))
                (out / f"row-{label}.json").write_text(json.dumps(row, indent=1))
                print(json.dumps({k: row.get(k) for k in ("label", "calibrate_wall_s", "runs")}),
                      file=sys.stderr, flush=True)
    rows = [json.loads(f.read_text()) for f in sorted(out.glob("row-*.json"))]
    print(table(rows, speeds))
    return 0


if __name__ == "__main__":
    sys.exit(main())
