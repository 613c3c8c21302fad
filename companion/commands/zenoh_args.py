"""The ``--zenoh-*`` flags shared by ``companion run``, ``demo``, ``monitor``, ``control`` and ``router``."""

from __future__ import annotations

import argparse


def _at_least_one(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, not {value}")
    return value


def add_zenoh_arguments(p: argparse.ArgumentParser, vehicle: bool = True,
                        modes: tuple[str, ...] = ("peer", "client"),
                        roles: tuple[str, ...] | None = None) -> None:
    """``roles``: the certificate roles the command accepts with --zenoh-tls (a vehicle's
    command: rover)."""
    p.set_defaults(zenoh_roles=roles if roles is not None else (("rover",) if vehicle else ()))
    g = p.add_argument_group(
        "zenoh (live telemetry and remote control)",
        "By default an embedded Zenoh peer (no router needed) with Zenoh's default discovery. "
        "Flags override --zenoh-config FILE (else $ZENOH_CONFIG).")
    if vehicle:
        g.add_argument("--no-zenoh", dest="zenoh", action="store_false",
                       help="publish nothing and open no Zenoh session")
    g.add_argument("--zenoh-connect", action="append", default=[], metavar="ENDPOINT",
                   help="connect to this Zenoh endpoint, e.g. tcp/10.0.0.2:7447 (repeatable)")
    g.add_argument("--zenoh-listen", action="append", default=[], metavar="ENDPOINT",
                   help="listen on this Zenoh endpoint, e.g. tcp/0.0.0.0:7448 (repeatable)")
    g.add_argument("--zenoh-config", metavar="FILE", help="a Zenoh JSON5 config file")
    if len(modes) > 1:
        g.add_argument("--zenoh-mode", choices=modes, default=None,
                       help="peer (default) or client (all traffic through the router "
                            "given with --zenoh-connect)")
    g.add_argument("--zenoh-scouting", action=argparse.BooleanOptionalAction, default=None,
                   help="multicast scouting (finding peers on the LAN); default: Zenoh's (on)")
    g.add_argument("--zenoh-tls", metavar="DIR/NAME",
                   help="mutual TLS with DIR/NAME.pem and DIR/NAME.key, issued by the CA "
                        "DIR/ca.pem (companion pki); every endpoint must then be "
                        "tls/HOST:PORT, and access control enforces the certificate's role")
    if vehicle:
        g.add_argument("--vehicle-id", metavar="ID",
                       help="the <vehicle_id> in rover/<vehicle_id>/... (default rover<sysid>)")
        g.add_argument("--state-every", type=_at_least_one, default=1, metavar="N",
                       help="publish state every N-th control cycle (default 1: every cycle)")
        g.add_argument("--control-secret", metavar="FILE",
                       help="enable the rover/<vehicle_id>/control queryable; requests must "
                            "carry this file's secret (the file must be chmod 600)")


def bus_options(args: argparse.Namespace, mode: str | None = None):
    from ..bus import BusOptions
    return BusOptions(
        enabled=getattr(args, "zenoh", True),
        mode=mode or getattr(args, "zenoh_mode", None),
        connect=tuple(args.zenoh_connect), listen=tuple(args.zenoh_listen),
        config_file=args.zenoh_config, scouting=args.zenoh_scouting,
        vehicle_id=getattr(args, "vehicle_id", None),
        state_every=getattr(args, "state_every", 1),
        control_secret=getattr(args, "control_secret", None),
        tls=getattr(args, "zenoh_tls", None), roles=tuple(getattr(args, "zenoh_roles", ())))
