"""``companion mission pull --connect URL [--out FILE.plan]``: the vehicle's stored mission as a
QGroundControl .plan (:mod:`companion.live.vehicle_mission`); and ``run --mission vehicle``'s
pull before a flight."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from ..app.arguments import BAUD_HELP, CONNECT_HELP, at_least_one, baud_rate, mavlink_id, positive
from ..errors import UserError

VEHICLE = "vehicle"      # companion run --mission vehicle


def register(sub) -> None:
    p = sub.add_parser(
        "pull", help="read the mission stored on the vehicle into a .plan",
        description="Read the vehicle's mission with the MAVLink mission protocol "
                    "(MISSION_REQUEST_LIST / MISSION_REQUEST_INT, retried) and write it as a "
                    "QGroundControl .plan. A partial transfer writes nothing. Exit 0 written, "
                    "2 no vehicle or no answer, 3 the transfer broke off.")
    p.add_argument("--connect", metavar="URL", required=True, help=CONNECT_HELP)
    p.add_argument("--baud", type=baud_rate, metavar="BPS", help=BAUD_HELP)
    p.add_argument("--sysid", type=int, metavar="N",
                   help="system id of the vehicle (default: the first heartbeat's)")
    p.add_argument("--source-system", type=mavlink_id, metavar="N",
                   help="the companion's own system id (default: the vehicle's)")
    p.add_argument("--out", metavar="FILE.plan", help="where to write (default: stdout)")
    p.add_argument("--timeout", type=positive, default=1.5, metavar="S",
                   help="wall s to wait for each answer (default 1.5)")
    p.add_argument("--retries", type=at_least_one, default=5, metavar="N",
                   help="times each request is sent again (default 5)")
    p.add_argument("--heartbeat-timeout", type=positive, default=10.0, metavar="S",
                   help="wait this long for the vehicle's heartbeat (default 10)")
    p.add_argument("--signing-key", metavar="FILE", help="MAVLink 2 signing key file")
    p.add_argument("-q", "--quiet", action="store_true", help="no log lines on stderr")
    p.set_defaults(func=run_pull)


def pull(url: str, sysid: int | None, baud: int | None, source_system: int | None,
         signing_key: bytes | None, heartbeat_timeout: float, timeout: float, retries: int,
         log):
    from ..live.config import LinkConfig
    from ..live.vehicle_mission import pull_plan
    from ..mav.mission_transfer import TransferConfig
    config = LinkConfig(url=url, sysid=sysid, baud=baud, source_system=source_system,
                        signing_key=signing_key, heartbeat_timeout=heartbeat_timeout)
    return pull_plan(config, TransferConfig(timeout=timeout, retries=retries), log)


def run_pull(args) -> int:
    from ..app.flight import logger, signing_key
    from ..live.vehicle_mission import write_plan
    log = logger("companion mission pull", args.quiet)
    pulled = pull(args.connect, args.sysid, args.baud, args.source_system,
                  signing_key(args.signing_key), args.heartbeat_timeout, args.timeout,
                  args.retries, log)
    plan, count = pulled.plan, pulled.count
    if args.out:
        if Path(args.out).suffix.lower() != ".plan":
            from ..errors import UserError
            raise UserError(f"--out {args.out}: a QGroundControl .plan is written: name it "
                            "FILE.plan")
        write_plan(plan, args.out)
        log(f"{count} items written to {args.out}")
    else:
        sys.stdout.write(json.dumps(plan, indent=2) + "\n")
    return 0


def vehicle_mission_file(options, log):
    """``run --mission vehicle``: pull the stored mission, keep it beside the flight logs (or in
    a temporary folder with --no-log): (its path, the Pulled mission)."""
    import tempfile

    from ..app.flight import signing_key
    from ..live.vehicle_mission import write_plan
    link = options.link
    key = signing_key(options.signing_key_file)      # read once, however often it pulls

    def pulled_now():
        return pull(link.url, link.sysid, link.baud, link.source_system, key,
                    link.heartbeat_timeout, 1.5, 5, log)
    pulled = pulled_now()
    if pulled.homeless:
        pulled = _wait_for_home(pulled, pulled_now, options.origin.timeout, log)
    folder = Path(options.log.folder or "logs") if options.log.enabled else \
        Path(tempfile.mkdtemp(prefix="pzc-vehicle-mission-"))
    folder.mkdir(parents=True, exist_ok=True)
    path = write_plan(pulled.plan, folder / time.strftime("vehicle-mission-%Y%m%d-%H%M%S.plan"))
    log(f"pulled the vehicle's mission: {pulled.count} items, kept as {path}")
    return path, pulled


HOME_POLL = 2.0        # wall s between pulls while the vehicle has no home


def _wait_for_home(pulled, pull_again, timeout: float, log):
    """The mission pulled again until the vehicle's home is in it (ArduPilot writes it into item
    0 at its first GPS fix, about 10 s after boot), at most ``timeout`` s: a home of 0, 0 is no
    place to start from. A UserError (exit 2) naming what it waited for if it never came."""
    log(f"the vehicle's mission has no home yet (0, 0: {pulled.profile.label} sets it at its "
        f"first GPS fix): waiting up to {timeout:g} s (--origin-timeout) for it")
    started = time.monotonic()
    while pulled.homeless:
        if time.monotonic() - started >= timeout:
            raise UserError(f"--mission vehicle: the vehicle's mission still had no home after "
                            f"{timeout:g} s (no GPS fix?): nowhere to place it")
        time.sleep(HOME_POLL)
        pulled = pull_again()
    home = pulled.plan["mission"]["plannedHomePosition"]
    log(f"the vehicle's home is set after {time.monotonic() - started:.0f} s of waiting: "
        f"{home[0]:.7f}, {home[1]:.7f}")
    return pulled


def handover_plan(pulled):
    """``run --handover``: the segments of the pulled mission (a UserError if the autopilot has
    no guided sub-mode in its missions, or a segment is malformed)."""
    from ..errors import UserError
    from ..live.handover import HandoverPlan, segments
    if pulled.profile.auto_mode is None:
        raise UserError(f"--handover: {pulled.profile.label} has no guided sub-mode inside a "
                        "mission (ArduPilot's NAV_GUIDED_ENABLE); see docs/ground-station.md")
    found = segments(pulled.items)
    if not found:
        raise UserError("--handover: the vehicle's mission has no NAV_GUIDED_ENABLE 1 ... "
                        "NAV_GUIDED_ENABLE 0 segment for the companion")
    return HandoverPlan(found, len(pulled.items) - 1)
