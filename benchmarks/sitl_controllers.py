"""The paper's comparison on the real autopilot: PZC, PID and Kanayama flying ArduPilot Rover SITL.

Boots one ``ardurover`` (stock ``rover-skid``, or ``--model rover``: the Ackermann car on
rover.parm alone; ``--param NAME=VALUE`` for another vehicle) and
flies ``companion run --controller C`` for every controller of :mod:`companion.core.controllers`
on the paper's ellipse (``missions/paper_ellipse_0xx.toml``: 60 s, anchored at the rover's start
pose) at each ``--f-r``, 40 Hz telemetry, in two configurations:

* ``defaults``: no vehicle file, what a new user gets (pzc: the bundled vehicle the SITL's
  parameters match, on stock ``rover-skid`` the ``ardupilot-skid`` preset's gains and limits;
  with ``--param`` changing one of them, the shipped gains for 40 Hz and the mission's w_c, the
  default limits 6 m/s, 6 rad/s, and a warning: docs/flying.md);
* ``calibrated``: ``--vehicle companion/sim/vehicles/ardupilot_skid.toml``, the vehicle
  ``companion calibrate`` identified on this very SITL model (pzc: the gains file beside it; the
  vehicle's own limits).

PID flies its default gains in both (the paper's k_P 3.5, k_I 0.5, k_D 0.5); Kanayama its
defaults in ``defaults`` and, in ``calibrated``, the gains picked by hand for the frame
(``benchmarks/kanayama_gains.toml``: ``[skid]`` for ``rover-skid``, ``[ackermann]`` for
``rover``; the classical baseline of issue 20, whose defaults limit-cycle on these rovers), all
within the same limits as pzc. Then ArduPilot's own GUIDED
position-target following (:func:`testbed.baselines.follow`) flies each speed. Scored as
``benchmarks/sitl_tracking.py`` scores: the steady RMS of |p_ref - p| over the last 30 s and
f_cost, both from the vehicle's own LOCAL_POSITION_NED; and the share of that time the yaw-rate
setpoint sat at its limit (a limit cycle shows as a large share). Prints one markdown table and
the command that made it (``--json``: one object instead).

    python benchmarks/sitl_controllers.py [--f-r 0.04,0.08] [--speedup 1] [--no-native] [--json]

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

from companion.core import controllers
from testbed.baselines import kanayama_argv
from testbed.missions import PAPER_ELLIPSES
from testbed.process import ROOT
from testbed.scoring import at_limit_share

CALIBRATED = "companion/sim/vehicles/ardupilot_skid.toml"
CONFIGS = {"defaults": [], "calibrated": ["--vehicle", CALIBRATED]}
NATIVE = "ardupilot-guided"     # the controller column of ArduPilot's own following
FRAMES = {"rover-skid": "skid", "rover": "ackermann"}   # SITL --model -> kanayama_gains.toml


def controller_argv(controller: str, config: str, model: str) -> list[str]:
    """``--controller C``, and for Kanayama in the calibrated configuration the gains picked by
    hand for the SITL model's frame (its defaults on a model without any)."""
    if controller == "kanayama" and CONFIGS[config] and model in FRAMES:
        return kanayama_argv(FRAMES[model])
    return ["--controller", controller]


def fly(url: str, controller: str, f_r: float, config: str, logs: Path,
        vehicle: str = CALIBRATED, model: str = "rover-skid") -> dict:
    """One ``companion run``: its JSON result, or the exit code and the tail of its stderr.
    ``vehicle``: the calibrated configuration's vehicle file; ``model``: the SITL frame."""
    flags = ["--vehicle", vehicle] if CONFIGS[config] else []
    argv = [sys.executable, "-m", "companion", "run", "--connect", url, "--mission",
            str(PAPER_ELLIPSES[f_r]), *flags,
            *controller_argv(controller, config, model),
            "--arm", "--json", "--no-zenoh", "--log-dir", str(logs), "-q",
            # the first run waits for SITL's boot (GPS, EKF origin, arming: about 40 s)
            "--telemetry-timeout", "90", "--arm-timeout", "120"]
    p = subprocess.run(argv, capture_output=True, text=True, timeout=600, cwd=ROOT)
    lines = p.stdout.strip().splitlines()
    try:
        result = json.loads(lines[-1])
    except (IndexError, json.JSONDecodeError):
        return {"exit_code": p.returncode, "reason": p.stderr.strip()[-300:]}
    return result


def row_of(result: dict, controller: str, f_r: float, config: str) -> dict:
    limits = result.get("limits") or {}
    yaw_limit = limits.get("max_yaw_rate")
    csv = result.get("csv")
    return {"f_r": f_r, "config": config, "controller": controller,
            "exit_code": result.get("exit_code"), "reason": result.get("reason"),
            "steady_rms": result.get("steady_rms"), "f_cost": result.get("f_cost"),
            "at_limit": (at_limit_share(csv, yaw_limit) if csv and yaw_limit else None),
            "gains_source": result.get("gains_source"), "limits": limits,
            "loop_rate_hz": result.get("loop_rate_hz")}


def number(value, fmt: str) -> str:
    return "n/a" if value is None or not math.isfinite(value) else format(value, fmt)


def kanayama_text(out: dict) -> str:
    """What Kanayama flew in the calibrated configuration, as its rows' results say."""
    flown = {r.get("gains_source") for r in out["rows"]
             if r["controller"] == "kanayama" and r["config"] == "calibrated"}
    flown.discard(None)
    return "; ".join(sorted(flown)) or "n/a"


def table(out: dict) -> str:
    """The markdown table, with its header (what was flown, the gains, the limits) and command."""
    rows = out["rows"]
    pid, kan = controllers.get("pid"), controllers.get("kanayama")
    limits = {}
    for r in rows:
        if r["controller"] != NATIVE and r["limits"]:
            limits.setdefault(r["config"], r["limits"])
    lim_text = "; ".join(f"{c} {number(l.get('max_speed'), '.3g')} m/s, "
                         f"{number(l.get('max_yaw_rate'), '.3g')} rad/s"
                         for c, l in limits.items())
    lines = [
        f"ArduPilot Rover SITL `{out.get('model', 'rover-skid')}` {out['params'] or '(stock)'}, speedup "
        f"{out['speedup']:g}, measured {out['date']}: the paper's ellipse, 60 s at 40 Hz, "
        "anchored at the start pose; steady RMS of |p_ref - p| over the last 30 s and f_cost "
        "from the vehicle's LOCAL_POSITION_NED; yaw@limit: share of those 30 s with the "
        "yaw-rate setpoint at its limit.",
        "",
        f"Gains: pzc as `companion run` picks them (defaults: the shipped tuned gains; "
        f"calibrated: the gains file beside `{out.get('vehicle', CALIBRATED)}`); pid its defaults, "
        f"not tuned for this vehicle: {pid.defaults_source()}; kanayama in defaults: "
        f"{kan.defaults_source()}, in calibrated: {kanayama_text(out)}. "
        f"Limits, the same for all three controllers: {lim_text or 'n/a'}.",
        "",
        "| f_r (Hz) | configuration | controller | steady RMS (m) | f_cost | yaw@limit | exit |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        at = r.get("at_limit")
        lines.append(
            f"| {r['f_r']:g} | {r['config']} | {r['controller']} | "
            f"{number(r.get('steady_rms'), '.3f')} | {number(r.get('f_cost'), '.2f')} | "
            f"{'-' if at is None else format(100 * at, '.0f') + ' %'} | "
            f"{r.get('exit_code', '-') if r.get('exit_code') is not None else '-'} |")
    lines += ["", f"command: `{out['command']}`"]
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default="rover-skid",
                   help="SITL frame: rover-skid (default) or rover (Ackermann, rover.parm only)")
    p.add_argument("--f-r", default="0.04,0.08", help="ellipse speeds (of 0.04, 0.08, 0.12)")
    p.add_argument("--controllers", default=",".join(controllers.NAMES))
    p.add_argument("--configs", default=",".join(CONFIGS), help="defaults, calibrated")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="an ArduPilot parameter for this vehicle (repeatable)")
    p.add_argument("--vehicle", default=CALIBRATED, metavar="FILE",
                   help=f"the calibrated configuration's vehicle file (default {CALIBRATED})")
    p.add_argument("--speedup", type=float, default=1.0, help="SITL speedup (default 1)")
    p.add_argument("--no-native", dest="native", action="store_false",
                   help="skip ArduPilot's own GUIDED following")
    p.add_argument("--keep", metavar="DIR", help="keep the flight logs here")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    from testbed.ardupilot import ArduPilotSITL

    params = {k: float(v) for k, v in (item.split("=", 1) for item in args.param)}
    speeds = [float(v) for v in args.f_r.split(",")]
    names = args.controllers.split(",")
    configs = args.configs.split(",")
    for name in names:
        controllers.get(name)
    bad = [c for c in configs if c not in CONFIGS] + [f for f in speeds if f not in PAPER_ELLIPSES]
    if bad:
        p.error(f"unknown configuration or speed: {bad}")
    out = {"date": datetime.date.today().isoformat(), "speedup": args.speedup, "params": params,
           "model": args.model, "vehicle": args.vehicle,
           "command": shlex.join(["python", "benchmarks/sitl_controllers.py", *sys.argv[1:]]),
           "rows": []}
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="sitl-controllers-") as tmp:
        logs = Path(args.keep) if args.keep else Path(tmp) / "logs"
        sitl = ArduPilotSITL(Path(tmp) / "sitl", speedup=args.speedup, params=params,
                             model=args.model).start()
        try:
            url = sitl.url(0)
            for f_r in speeds:
                for config in configs:
                    for name in names:
                        row = row_of(fly(url, name, f_r, config, logs, args.vehicle,
                                         args.model), name, f_r, config)
                        out["rows"].append(row)
                        print(json.dumps(row), file=sys.stderr, flush=True)
                if args.native:
                    from companion import mission as missions
                    from testbed.baselines import follow
                    r = follow(url, missions.paper_ellipse(f_r, 60.0), arm=True)
                    out["rows"].append({"f_r": f_r, "config": "-", "controller": NATIVE,
                                        "steady_rms": r["steady_rms"], "f_cost": r["f_cost"],
                                        "limits": {}})
                    print(json.dumps(out["rows"][-1]), file=sys.stderr, flush=True)
        finally:
            sitl.stop()
    out["wall_s"] = time.monotonic() - t0
    if args.json:
        print(json.dumps(out))
    else:
        print(table(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
