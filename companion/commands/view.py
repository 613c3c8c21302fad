"""``companion view``: every rover on the Zenoh bus, live in the browser (Rerun's web viewer).

Subscribes to ``rover/*/state`` and ``rover/*/status`` (it publishes nothing: the rovers do not
slow down for it) and draws, per rover, the reference path and the path driven on a map in
local metres, the rover coloured by its state, its error and setpoints over time, its
life-cycle events and failsafes, and a table of the fleet; a rover that stops publishing for
``--stale-after`` seconds is drawn grey and labelled STALE. Rerun's SDK serves the stream
(``--grpc-port``) and its web viewer (``--web-port``) from this machine: open the printed URL,
no internet needed. The Zenoh flags are the bus's own (mutual TLS with ``--zenoh-tls DIR/NAME``,
a monitor's or an operator's certificate).
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import sys
import time

from ..app.arguments import add_zenoh_arguments, port_number, positive
from ..app.options import bus_options


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "view", help="live fleet view in the browser (Rerun web viewer, served locally)",
        description=__doc__.split("\n\n", 1)[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--web-port", type=port_number, default=9090, metavar="PORT",
                   help="the web viewer's HTTP port (default 9090)")
    p.add_argument("--grpc-port", type=port_number, default=9876, metavar="PORT",
                   help="the port Rerun streams the data on (default 9876)")
    p.add_argument("--refresh", type=positive, default=0.1, metavar="S",
                   help="redraw every S seconds (default 0.1)")
    p.add_argument("--stale-after", type=positive, default=2.0, metavar="S",
                   help="a rover silent this long is shown stale (default 2)")
    p.add_argument("--duration", type=positive, metavar="S",
                   help="exit after S seconds (default: until Ctrl-C / SIGTERM)")
    p.add_argument("--key", default="rover/*", metavar="KEYEXPR",
                   help="vehicles to watch (default rover/*)")
    p.add_argument("--json", action="store_true",
                   help="print the URL, then on exit what was drawn, as JSON lines")
    add_zenoh_arguments(p, vehicle=False, roles=("monitor", "operator"))
    p.set_defaults(func=run)


def run(args) -> int:
    import zenoh  # noqa: F401  (fail here, not inside a callback, if it is missing)

    from ..bus.session import session_until_signal
    from ..view.draw import Drawing, _require
    from ..view.fleet import Fleet

    _require()                      # a missing SDK is a one-line error before the session
    fleet = Fleet(stale_after=args.stale_after)
    cpu0, t0 = _cpu(), time.monotonic()
    with session_until_signal(bus_options(args)) as (session, stop):
        drawing = _open_drawing(Drawing, args)
        for kind in ("state", "status"):
            session.declare_subscriber(f"{args.key}/{kind}", fleet.on_sample)
        if args.json:
            print(json.dumps({"url": drawing.url, "grpc": drawing.grpc_url}), flush=True)
        else:
            print(f"fleet view: open {drawing.url}", flush=True)
        end = t0 + (args.duration or math.inf)
        while not stop.is_set() and time.monotonic() < end:
            drawing.draw(fleet.take())
            stop.wait(min(args.refresh, max(0.0, end - time.monotonic())))
        rovers = fleet.take()
    summary = {"samples": fleet.samples, "bad": fleet.bad, "frames": drawing.frames,
               "rovers": {r.vehicle_id: {"state_msgs": r.state_msgs, "stale": r.stale,
                                         "phase": r.phase} for r in rovers},
               "wall_s": round(time.monotonic() - t0, 3), "cpu_s": round(_cpu() - cpu0, 3)}
    if args.json:
        print(json.dumps(summary), flush=True)
    else:
        print(f"fleet view: {summary['samples']} samples, {summary['frames']} frames drawn, "
              f"{summary['cpu_s']:.1f} s CPU over {summary['wall_s']:.1f} s", file=sys.stderr)
    return 0


def _open_drawing(Drawing, args):
    from ..errors import UserError
    try:
        return Drawing(args.grpc_port, args.web_port)
    except Exception as exc:  # noqa: BLE001  (Rerun raises RuntimeError for a busy port, ...)
        raise UserError(f"cannot serve the view on --web-port {args.web_port} / --grpc-port "
                        f"{args.grpc_port}: {exc}") from None


def _cpu() -> float:
    """CPU seconds of this process (Zenoh's, Rerun's and our threads together)."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime
