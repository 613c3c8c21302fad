"""Sim-to-real: the same companion, gains and mission on the bundled plant and on ArduPilot SITL.

For each gains file and each speed of the paper's ellipse, ``companion demo`` flies it against
``sitl-plant --vehicle FILE`` (the identified model, lockstep: seconds) and, with ``--sitl``,
``companion run`` flies it against ArduPilot Rover SITL (``rover-skid``; one instance booted for
every run, extra parameters with ``--param NAME=VALUE``). With ``--native`` ArduPilot's own
GUIDED position-target following flies each speed too (:mod:`native_follow`). It prints, per
row, the steady RMS over the last 30 s on each side, the share of that time the yaw-rate setpoint
sat at its limit (a limit cycle) and whether plant and vehicle agree (within 25 % or 0.05 m).

    python benchmarks/sim_to_real.py --vehicle V.toml --gains A.toml --gains B.toml \\
        --f-r 0.04,0.08 --sitl [--native] [--speedup 1] [--json]

Needs ``ARDUPILOT_SITL`` (or ``ARDUPILOT_DIR``) for ``--sitl``; prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

MISSIONS = {0.04: "paper_ellipse_004.toml", 0.08: "paper_ellipse_008.toml",
            0.12: "paper_ellipse_012.toml"}
KANAYAMA_GAINS = ROOT / "benchmarks" / "kanayama_gains.toml"


def at_limit_share(csv_path: str, limit: float, duration: float = 60.0) -> float:
    """Share of the last half's cycles with the yaw-rate setpoint at its limit (from the CSV)."""
    values = []
    with open(csv_path) as f:
        for row in csv.DictReader(f):
            try:
                t, w = float(row["mission_time"]), float(row["yaw_rate_cmd"])
            except (TypeError, ValueError):
                continue
            if t >= duration / 2:
                values.append(abs(w) >= 0.98 * limit)
    return sum(values) / len(values) if values else math.nan


def companion(argv: list[str], timeout: float) -> dict:
    """``companion ARGV`` as a process; its JSON result (the last stdout line), or exit with
    the tail of its stderr."""
    p = subprocess.run([sys.executable, "-m", "companion", *argv], capture_output=True,
                       text=True, timeout=timeout, cwd=ROOT)
    if p.returncode != 0:
        raise SystemExit(f"companion {argv[0]}: exit {p.returncode}: {p.stderr.strip()[-600:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def ready_argv(url: str, folder: Path) -> list[str]:
    """``companion`` arguments of a short stand-still mission (written into ``folder``), flown
    first so that a timed command's clock starts on a booted vehicle (GPS fix, EKF position,
    arming checks: about 45 s on a fresh SITL, not the command's time; the run waits for the
    estimate itself, up to its --estimate-wait). The benchmarks that boot SITL share it."""
    mission = folder / "ready.toml"
    folder.mkdir(parents=True, exist_ok=True)
    mission.write_text('name = "ready"\nframe = "start"\nduration = 1\n[trajectory]\n'
                       'kind = "ellipse"\nf_r = 0.01\nax = 0\nbx = 0\nay = 0\nby = 0\n')
    return ["run", "--connect", url, "--mission", str(mission), "--arm", "--json",
            "--no-zenoh", "--no-log", "-q", "--telemetry-timeout", "90",
            "--arm-timeout", "120", "--lost-timeout", "120"]


def kanayama_argv(frame: str) -> list[str]:
    """``companion run`` arguments flying Kanayama's law with the gains picked by hand for the
    vehicle kind ``frame`` ("skid" or "ackermann", :data:`KANAYAMA_GAINS`): the classical
    baseline issue 20 compares with, not its defaults, which limit-cycle on ArduPilot's rovers.
    The benchmarks that fly it share it."""
    import tomllib
    gains = tomllib.loads(KANAYAMA_GAINS.read_text())[frame]
    return ["--controller", "kanayama", "--controller-gains",
            ",".join(f"{name}={float(value):g}" for name, value in gains.items())]


def wait_ready(url: str, folder: Path, timeout: float = 300) -> float:
    """The stand-still mission of :func:`ready_argv`, flown; the wall seconds it took."""
    import time
    t0 = time.monotonic()
    companion(ready_argv(url, folder), timeout)
    return time.monotonic() - t0


def limit_flags(vehicle) -> list[str]:
    out = []
    if math.isfinite(vehicle.max_speed):
        out += ["--max-speed", repr(float(vehicle.max_speed))]
    if math.isfinite(vehicle.max_yaw_rate):
        out += ["--max-yaw-rate", repr(float(vehicle.max_yaw_rate))]
    return out


def on_plant(vehicle_path: str, gains: str, f_r: float, logs: Path, limits: list[str]) -> dict:
    r = companion(["demo", "--vehicle", vehicle_path, "--mission",
                    str(ROOT / "missions" / MISSIONS[f_r]), "--gains", gains, *limits,
                    "--d-cen", "0", "--json", "--no-plot", "--no-zenoh", "--log-dir", str(logs),
                    "-q"], timeout=300)
    return r


def on_sitl(url: str, gains: str, f_r: float, logs: Path, limits: list[str]) -> dict:
    return companion(["run", "--connect", url, "--mission", str(ROOT / "missions" / MISSIONS[f_r]),
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
            from ardupilot_harness import ArduPilotSITL
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
                from native_follow import follow
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
