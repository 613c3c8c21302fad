"""``companion``: the command-line entry point.

Each sub-command lives in its own module under :mod:`companion.commands` and exposes
``register(subparsers)``, which adds its parser and sets ``func(args) -> int``. Heavy imports
(numpy simulation, pymavlink, zenoh) happen inside ``func`` so ``--help`` stays instant.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from . import __version__
from .app import config_file
from .errors import ExitCode, UserError

# Sub-command modules, in the order ``companion --help`` lists them.
COMMANDS = [
    "demo",
    "run",
    "paper_table",
    "tune",
    "identify",
    "calibrate",
    "preflight",
    "mission",
    "simulate",
    "monitor",
    "view",
    "control",
    "router",
    "plot",
    "report",
    "log",
    "pki",
]


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (plus the usage) and exit code 2, as before."""


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="companion", description=(
        "Companion-computer trajectory tracker for skid-steer and Ackermann rovers on ArduPilot "
        "and PX4: the model-free filter and PZC PI law of Lee et al. (2024), over MAVLink."))
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"companion.commands.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:   # --config FILE fills a command's flags (companion.app.config_file)
        args = config_file.parse_args(parser, argv)
    except config_file.ConfigError as err:
        print(f"{err.prog}: error: {err}", file=sys.stderr)
        return err.exit_code
    try:
        return int(args.func(args) or 0)
    except UserError as err:
        print(f"companion {args.command}: error: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt:
        print(f"companion {args.command}: interrupted", file=sys.stderr)
        return ExitCode.INTERRUPTED
    except BrokenPipeError:
        return ExitCode.OK


if __name__ == "__main__":
    sys.exit(main())
