"""``companion``: the command-line entry point.

Each sub-command lives in its own module under :mod:`companion.commands` and exposes
``register(subparsers)``, which adds its parser and sets ``func(args) -> int``. Heavy imports
(numpy simulation, pymavlink, zenoh) happen inside ``func`` so ``--help`` stays instant, and
only the named command's module is imported (every one for ``companion --help``, ``--version``
or a name that is not a command, so argparse can list them): a ``run`` on the rover's board
starts without the other seventeen.
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


def named_command(argv: list[str]) -> str | None:
    """The module of the command ``argv`` names first (``paper-table``: ``paper_table``), or
    None when it names none (a top-level flag comes first, or a word that is no command)."""
    if not argv or argv[0].startswith("-"):
        return None
    module = argv[0].replace("-", "_")
    return module if module in COMMANDS else None


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or (``only``, a module of :data:`COMMANDS`) of that one."""
    parser = _Parser(prog="companion", description=(
        "Companion-computer trajectory tracker for skid-steer and Ackermann rovers on ArduPilot "
        "and PX4: the model-free filter and PZC PI law of Lee et al. (2024), over MAVLink."))
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS if only is None else [only]:
        importlib.import_module(f"companion.commands.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(named_command(argv))
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
