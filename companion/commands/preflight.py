"""``companion preflight``: is the autopilot set up for the companion? One line per check.

Reads the vehicle's parameters (PARAM_REQUEST_LIST, then PARAM_REQUEST_READ for what was lost)
and its status (SYS_STATUS, EKF_STATUS_REPORT, GPS_GLOBAL_ORIGIN, the pose streams at the loop's
rate), and checks: the vehicle type and steering, the link's protocol and stream rates, the EKF
origin and position estimate, the pre-arm state, GUIDED / OFFBOARD, the failsafes that involve
the companion, the inner-loop limits the vehicle model uses, and signing. ``--fix --yes`` sets the
recommended failsafe values (PARAM_SET, read back and reported). Nothing arms, changes mode or
moves the rover.
"""

from __future__ import annotations

import argparse
import json
import sys

from ..app.arguments import BAUD_HELP, baud_rate, mavlink_id, positive
from ..app.flight import logger, signing_key
from ..errors import UserError
from ..live.config import DEFAULT_RATE, LINK

EPILOG = """\
exit codes: 0 every check ok; 1 a warning or a failure; 2 could not check (no vehicle, no
parameters, a bad flag or file).
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "preflight", help="check the autopilot's settings for the companion (and fix them)",
        description=__doc__.split("\n\n", 1)[1], epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--connect", metavar="URL", required=True,
                   help="pymavlink connection string (the companion's link to the autopilot)")
    p.add_argument("--baud", type=baud_rate, metavar="BPS", help=BAUD_HELP)
    p.add_argument("--sysid", type=int, metavar="N", help="system id of the vehicle")
    p.add_argument("--source-system", type=mavlink_id, metavar="N",
                   help="the companion's system id to check the GCS failsafe for, as `run "
                        "--source-system` (default: the vehicle's)")
    p.add_argument("--rate", type=positive, default=DEFAULT_RATE, metavar="HZ",
                   help=f"pose telemetry rate the control loop will ask for (default {DEFAULT_RATE:g})")
    p.add_argument("--vehicle", metavar="FILE",
                   help="the rover's vehicle file: hold its limits against the autopilot's")
    p.add_argument("--signing-key", metavar="FILE",
                   help="MAVLink 2 signing key the companion uses (checks the vehicle's "
                        "signature)")
    p.add_argument("--heartbeat-timeout", type=positive, default=LINK.heartbeat_timeout,
                   metavar="S", help="wait this long for the vehicle's heartbeat "
                                     f"(default {LINK.heartbeat_timeout:g})")
    p.add_argument("--fix", action="store_true",
                   help="set the recommended values (PARAM_SET, read back); asks first")
    p.add_argument("--yes", action="store_true", help="with --fix: do not ask")
    p.add_argument("--json", action="store_true",
                   help='print {"checks": [{"name", "status", "value", "want", "why"}, ...]}')
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")
    from ..app.config_file import add_config_arguments
    add_config_arguments(p)
    p.set_defaults(func=run)


def _limits(path: str | None):
    if path is None:
        return None
    from ..app.vehicle import load
    from ..preflight.checks import Limits
    params = load(path).params
    return Limits(max_speed=float(params.max_speed), max_accel=float(params.max_accel),
                  max_decel=float(params.decel), max_yaw_rate=float(params.max_yaw_rate),
                  max_yaw_accel=float(params.max_yaw_accel), source=f"--vehicle {path}")


def _is_serial(url: str) -> bool:
    return url.startswith("/dev/") or url.upper().startswith("COM")


def run(args) -> int:
    if args.yes and not args.fix:
        raise UserError("--yes confirms --fix; give both")
    limits = _limits(args.vehicle)          # a bad file fails before connecting
    key = signing_key(args.signing_key)
    from ..live.link import LinkConfig
    from ..preflight.checks import exit_code, fixes, run_checks
    from ..preflight.gather import GatherConfig, connect

    log = logger("companion preflight", args.quiet)
    cfg = GatherConfig(rate_hz=args.rate)
    link, probe = connect(LinkConfig(url=args.connect, sysid=args.sysid, signing_key=key,
                                     heartbeat_timeout=args.heartbeat_timeout, baud=args.baud,
                                     source_system=args.source_system))
    try:
        v = link.vehicle
        log(f"{v.autopilot} system {v.sysid} (MAV_TYPE {v.mav_type}): reading parameters")
        params = probe.read_params(cfg.param_timeout)
        log(f"{len(params)} parameters"
            + (f" of {probe.client.count}" if probe.client.count else "")
            + (f" ({probe.client.retried} asked for again)" if probe.client.retried else "")
            + "; reading status")
        probe.read_status(cfg.status_timeout)
        log(f"measuring pose telemetry at {cfg.rate_hz:g} Hz")
        streams = probe.measure_streams(cfg.rate_hz, cfg.measure_s)
        serial = _is_serial(args.connect)

        def observe():
            return probe.observed(streams, key is not None, serial, limits)
        rows = run_checks(observe())
        done = None
        if args.fix:
            plan = fixes(rows, {n: p.value for n, p in probe.params.items()})
            if plan and not args.yes and not _confirm(plan, probe):
                log("not confirmed: nothing set")
            else:
                done = probe.set_params(plan) if plan else []
                for row in done:
                    log(f"set {row['name']} {row['from']:g} -> {row['to']:g}: read back "
                        + ("nothing" if row["read_back"] is None else f"{row['read_back']:g}"))
                rows = run_checks(observe())
    finally:
        link.close()
    _print(rows, done, args.json)
    return exit_code(rows)


def _confirm(plan: dict[str, float], probe) -> bool:
    """Ask on the terminal (stderr, so --json stays one object on stdout)."""
    if not sys.stdin.isatty():
        raise UserError("--fix changes the autopilot's parameters: add --yes to confirm "
                        "(stdin is not a terminal)")
    for name, value in plan.items():
        print(f"  {name}: {probe.params[name].value:g} -> {value:g}", file=sys.stderr)
    print(f"set these {len(plan)} parameters? [y/N] ", end="", file=sys.stderr, flush=True)
    return sys.stdin.readline().strip().lower() in ("y", "yes")


def _print(rows, done, as_json: bool) -> None:
    if as_json:
        out = {"checks": [r.as_dict() for r in rows]}
        if done is not None:
            out["fixes"] = done
        print(json.dumps(out), flush=True)
        return
    lines = []
    if done is not None:
        if not done:
            lines.append("fix   nothing to set")
        for row in done:
            back = "no answer" if row["read_back"] is None else f"{row['read_back']:g}"
            lines.append(f"fix   {row['name']} {row['from']:g} -> {row['to']:g}, read back "
                         f"{back}" + ("" if row["ok"] else "  (NOT SET)"))
    width = max(len(r.name) for r in rows)
    for r in rows:
        lines.append(f"{r.status:<5} {r.name:<{width}}  {r.value}  [want {r.want}: {r.why}]")
    print("\n".join(lines), flush=True)
