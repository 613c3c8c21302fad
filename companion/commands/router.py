"""``companion router``: a Zenoh router in a Python process, for sites without ``zenohd``.

A session opened in ``router`` mode routes between the clients and peers that connect to it
(no separate binary: none is on PyPI). Fleets point each companion and monitor at it with
``--zenoh-connect tcp/HOST:7447`` (``--zenoh-mode client`` sends everything through it). Runs
until SIGTERM / Ctrl-C, then closes the session and exits 0. With ``--zenoh-tls DIR/NAME`` (a
router's certificate) it listens on ``tls/[::]:7447`` by default, admits only peers holding a
certificate from the CA in DIR, and enforces their roles (the certificates in DIR).
"""

from __future__ import annotations

import argparse
import sys

from ..app.arguments import add_zenoh_arguments
from ..app.options import bus_options

DEFAULT_LISTEN = "tcp/[::]:7447"
DEFAULT_TLS_LISTEN = "tls/[::]:7447"


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "router", help="run a Zenoh router (for fleets; no zenohd needed)",
        description=__doc__.split("\n\n", 1)[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    add_zenoh_arguments(p, vehicle=False, modes=("router",), roles=("router",))
    p.set_defaults(func=run)


def run(args) -> int:
    from ..bus.session import session_until_signal

    if not args.zenoh_listen and not args.zenoh_config:
        args.zenoh_listen = [DEFAULT_TLS_LISTEN if args.zenoh_tls else DEFAULT_LISTEN]

    def log(text: str) -> None:
        print(f"companion router: {text}", file=sys.stderr, flush=True)

    with session_until_signal(bus_options(args, mode="router"), default_mode="router",
                              log=log) as (session, stop):
        where = " ".join(args.zenoh_listen) or f"as in {args.zenoh_config}"
        print(f"companion router: routing, listening on {where} (zid {session.zid()})",
              file=sys.stderr, flush=True)
        while not stop.wait(1.0):
            pass
    print("companion router: stopped", file=sys.stderr, flush=True)
    return 0
