"""``companion control``: send one control request to a rover over Zenoh and print the reply.

The rover must run with ``--control-secret FILE``; pass the same secret with ``--secret FILE``.
With ``--zenoh-tls DIR/NAME`` the certificate must be an operator's (the secret stays a second
factor).
Exit code 0 when the rover did it, 1 when it refused (the reply says why), 2 for a user error or
no reply.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..app.arguments import add_zenoh_arguments, positive
from ..app.options import bus_options
from ..errors import UserError

VERBS = ("status", "start", "pause", "resume", "abort", "load-mission")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "control", help="send status/start/pause/resume/abort/load-mission to a rover over Zenoh",
        description=__doc__.split("\n\n", 1)[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("vehicle_id", metavar="VEHICLE_ID", help="e.g. rover1")
    p.add_argument("verb", choices=VERBS)
    p.add_argument("--secret", metavar="FILE", required=True,
                   help="file holding the rover's shared secret (chmod 600)")
    p.add_argument("--mission", metavar="FILE", help="for load-mission: the TOML mission file")
    p.add_argument("--timeout", type=positive, default=5.0, metavar="S")
    add_zenoh_arguments(p, vehicle=False, roles=("operator",))
    p.set_defaults(func=run)


def run(args) -> int:
    from ..bus.control import read_secret
    from ..bus.control_client import control_request
    from ..bus.session import close_all, close_session, open_session

    secret = read_secret(args.secret, "--secret")
    payload = None
    if args.verb == "load-mission":
        if not args.mission:
            raise UserError("load-mission needs --mission FILE")
        try:
            payload = Path(args.mission).read_bytes()
        except OSError as exc:
            raise UserError(f"--mission {args.mission}: cannot read: {exc.strerror}") from None
    elif args.mission:
        raise UserError(f"--mission is only for load-mission, not {args.verb}")
    session = None
    try:
        session = open_session(bus_options(args))
        reply = control_request(session, args.vehicle_id, args.verb, secret, payload,
                                args.timeout)
    finally:
        if session is not None:
            close_session(session)
        close_all()
    print(json.dumps(reply), flush=True)
    if not reply["ok"] and reply["message"].startswith("no reply"):
        print(f"companion control: error: {reply['message']}", file=sys.stderr)
        return 2
    return 0 if reply["ok"] else 1
