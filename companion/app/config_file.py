"""``--config FILE`` and ``--print-config`` for a sub-command: its flags from a TOML file.

The keys are read off the sub-command's own argparse parser, so every flag has one and a flag
added later has one too, with no second list to keep in sync:

* a key is the flag's destination name: the long flag without ``--``, ``-`` or ``_`` alike
  (``max_speed`` or ``max-speed`` for ``--max-speed``); an ``--no-X`` switch is ``X = false``
  (``log = false`` for ``--no-log``, ``zenoh = false`` for ``--no-zenoh``), or ``no_X = true``;
* a value is checked by the flag's own ``type=`` function and ``choices`` (a number or a string
  is given to it as the command line would be), so a bad value is refused with the same words as
  on the command line, naming the file and the key; switches take ``true`` / ``false``,
  repeatable flags (``--zenoh-connect``) an array;
* paths (flags whose metavar is FILE, DIR, DIR/NAME or LOG) are relative to the config file's
  folder, ``~`` is the home folder;
* flags given on the command line win over the file (a repeatable flag given on the command line
  replaces the file's list), the file wins over the defaults; a required flag may come from the
  file.

``--print-config`` prints the effective settings (flags > file > defaults) as TOML that
``--config`` reads back, paths made absolute, unset keys as comments, and exits 0 without doing
anything else.

Unknown keys, bad values and unreadable files are one line naming the file and key, exit 2.
"""

from __future__ import annotations

import argparse
import difflib
import json
import math
import os
import re
import sys
import tomllib
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from ..errors import UserError

NOT_KEYS = {"help", "version", "config", "print_config"}
PATH_METAVAR = re.compile(r"(FILE|DIR|LOG)\d*(/\w+)?")


class ConfigError(UserError):
    """A config file's mistake; ``prog`` is the command it belongs to (``companion run``)."""

    def __init__(self, prog: str, message: str):
        super().__init__(message)
        self.prog = prog


def add_config_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("config file")
    g.add_argument("--config", metavar="FILE",
                   help="read the flags from this TOML file (keys: the flags' names with _, "
                        "e.g. max_speed = 2.0, log = false for --no-log; paths relative to "
                        "the file); flags given here win")
    g.add_argument("--print-config", action="store_true",
                   help="print the effective settings as TOML (for --config) and exit")


def parse_args(parser: argparse.ArgumentParser, argv: Sequence[str] | None = None):
    """``parser.parse_args(argv)``, with each sub-command that has ``--config`` filled from its
    file (command line > file > defaults). Raises :class:`ConfigError` for a bad file;
    ``--print-config`` turns the command into printing its settings."""
    argv = list(sys.argv[1:] if argv is None else argv)
    subs = {name: sub for name, sub in _subparsers(parser).items() if _has_config(sub)}
    if not subs:
        return parser.parse_args(argv)
    with _only_given(subs.values()):
        given = parser.parse_args(argv)
    sub = subs.get(getattr(given, "command", ""))
    if sub is None:
        return parser.parse_args(argv)
    values: dict[str, Any] = {}
    if getattr(given, "config", None) is not None:
        values = load(given.config, sub)
    with _not_required(sub, values):
        args = parser.parse_args(argv)
    for dest, value in values.items():
        if not hasattr(given, dest):
            setattr(args, dest, value)
    if args.print_config:
        args.func = lambda a: print_config(a, sub)
    return args


def keyed_actions(sub: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    """dest -> action, for every flag of ``sub`` that a config file may set."""
    out: dict[str, argparse.Action] = {}
    for action in sub._actions:
        if (action.dest in NOT_KEYS or action.dest == argparse.SUPPRESS
                or isinstance(action, (argparse._HelpAction, argparse._VersionAction,
                                       argparse._SubParsersAction))):
            continue
        out.setdefault(action.dest, action)
    return out


def load(path: str, sub: argparse.ArgumentParser) -> dict[str, Any]:
    """The flags' values in the TOML file ``path``, each checked as on the command line."""
    def fail(message: str) -> ConfigError:
        return ConfigError(sub.prog, f"{path}: {message}")

    try:
        with open(path, "rb") as f:
            table = tomllib.load(f)
    except FileNotFoundError:
        raise fail("no such file") from None
    except OSError as exc:
        raise fail(exc.strerror or str(exc)) from None
    except tomllib.TOMLDecodeError as exc:
        raise fail(f"not valid TOML: {exc}") from None
    actions = keyed_actions(sub)
    folder = os.path.dirname(os.path.abspath(path))
    values: dict[str, Any] = {}
    seen: dict[str, str] = {}     # dest -> the key that set it
    negated = _negated_switches(actions)
    for key, raw in table.items():
        dest = key.replace("-", "_")
        action = actions.get(dest)
        if action is None and dest in negated and isinstance(raw, bool):
            dest, action = negated[dest]          # no_log = true: as --no-log, log = false
            raw = not raw
        if action is None:
            near = difflib.get_close_matches(dest, actions, n=1)
            hint = f" (did you mean {near[0]}?)" if near else ""
            if key in ("config", "print_config", "print-config"):
                hint = " (not allowed in a config file)"
            raise fail(f"unknown key {key!r}{hint}; the keys are {sub.prog}'s flags, "
                       f"see {sub.prog} --help")
        if dest in seen:
            raise fail(f"{key}: the same flag as {seen[dest]}, give one")
        seen[dest] = key
        try:
            value = _value(action, raw)
        except ValueError as exc:
            raise fail(f"{key}: {exc}") from None
        if _is_path(action) and value is not None:
            value = ([_resolve(folder, v) for v in value] if isinstance(value, list)
                     else _resolve(folder, value))
        values[dest] = value
    return values


def print_config(args: argparse.Namespace, sub: argparse.ArgumentParser) -> int:
    lines = [f"# {sub.prog}: effective settings (flags > config file > defaults); "
             "read back with --config"]
    for dest, action in keyed_actions(sub).items():
        value = vars(args).get(dest)   # every action of the parser has its dest set
        if value is None:
            metavar = action.metavar if isinstance(action.metavar, str) else ""
            flag = (f"{action.option_strings[-1]} {metavar}".strip() if action.option_strings
                    else f"the {metavar or dest} argument")
            lines.append(f"# {dest}: unset ({flag})")
            continue
        if _is_path(action):
            value = ([os.path.abspath(v) for v in value] if isinstance(value, list)
                     else os.path.abspath(value))
        lines.append(f"{dest} = {_toml(value)}")
    print("\n".join(lines), flush=True)
    return 0


# --- values ----------------------------------------------------------------------------------
def _value(action: argparse.Action, raw: Any) -> Any:
    """The value ``action`` would store for the TOML value ``raw`` (ValueError with the
    command line's words if it would refuse it)."""
    if isinstance(action, argparse._CountAction):
        if isinstance(raw, bool) or not isinstance(raw, int) or raw < 0:
            raise ValueError(f"must be a whole number >= 0, not {_toml(raw)}")
        return raw
    if isinstance(action, (argparse._StoreConstAction, argparse.BooleanOptionalAction)):
        if not isinstance(raw, bool):
            raise ValueError(f"must be true or false, not {_toml(raw)}")
        if isinstance(action, argparse.BooleanOptionalAction) or isinstance(action.const, bool):
            return raw
        return action.const if raw else action.default
    if isinstance(action, argparse._AppendAction):
        items = raw if isinstance(raw, list) else [raw]
        return [_one(action, item) for item in items]
    if action.nargs in (None, "?"):
        return _one(action, raw)
    items = raw if isinstance(raw, list) else [raw]
    if isinstance(action.nargs, int) and len(items) != action.nargs:
        raise ValueError(f"must be an array of {action.nargs} values, not {_toml(raw)}")
    if action.nargs == "+" and not items:
        raise ValueError("must be an array of at least one value")
    return [_one(action, item) for item in items]


def _one(action: argparse.Action, raw: Any) -> Any:
    if isinstance(raw, bool) or not isinstance(raw, (str, int, float)):
        raise ValueError(f"must be a number or a string, not {_toml(raw)}")
    text = raw if isinstance(raw, str) else repr(raw)
    convert: Any = action.type   # typeshed also admits a registry name (str): none used here
    if convert is None:
        value: Any = text
    else:
        try:
            value = convert(text)
        except argparse.ArgumentTypeError as exc:
            raise ValueError(str(exc)) from None
        except (TypeError, ValueError):
            name = getattr(convert, "__name__", repr(convert))
            raise ValueError(f"invalid {name} value: {text!r}") from None
    if action.choices is not None and value not in action.choices:
        choices = ", ".join(map(repr, action.choices))
        raise ValueError(f"invalid choice: {value!r} (choose from {choices})")
    return value


def _negated_switches(actions: dict[str, argparse.Action]) -> dict[str, tuple[str, Any]]:
    """``no_X`` -> (X, its action) for every ``--no-X`` switch storing a boolean X."""
    out = {}
    for dest, action in actions.items():
        boolean = (isinstance(action, argparse.BooleanOptionalAction)
                   or (isinstance(action, argparse._StoreConstAction)
                       and isinstance(action.const, bool)))
        for option in action.option_strings if boolean else ():
            name = option.lstrip("-").replace("-", "_")
            if name == f"no_{dest}":
                out[name] = (dest, action)
    return out


def _is_path(action: argparse.Action) -> bool:
    metavar = action.metavar
    return isinstance(metavar, str) and PATH_METAVAR.fullmatch(metavar) is not None


def _resolve(folder: str, value: str) -> str:
    return os.path.join(folder, os.path.expanduser(value))


def _toml(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ("nan" if math.isnan(value)
                                                         else ("inf" if value > 0 else "-inf"))
    if isinstance(value, str):
        return json.dumps(value)   # a TOML basic string: JSON's escapes are TOML's
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "a table"
    return json.dumps(str(value))


# --- argparse plumbing -----------------------------------------------------------------------
def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _has_config(sub: argparse.ArgumentParser) -> bool:
    return any(action.dest == "config" for action in sub._actions)


@contextmanager
def _only_given(subs) -> Iterator[None]:
    """While inside, parsing leaves out every flag not on the command line (no defaults, none
    required), so what remains is what the user typed."""
    saved = []
    for sub in subs:
        dests = {a.dest for a in sub._actions}
        saved.append((sub, sub._defaults, [(a, a.default, a.required) for a in sub._actions]))
        sub._defaults = {k: v for k, v in sub._defaults.items() if k not in dests}
        for action in sub._actions:
            action.default, action.required = argparse.SUPPRESS, False
    try:
        yield
    finally:
        for sub, defaults, actions in reversed(saved):   # an action shared by two parsers
            sub._defaults = defaults
            for action, default, required in actions:
                action.default, action.required = default, required


@contextmanager
def _not_required(sub: argparse.ArgumentParser, values: dict[str, Any]) -> Iterator[None]:
    """Required flags the file gave are not required on the command line."""
    changed = [a for a in sub._actions if a.required and a.dest in values]
    for action in changed:
        action.required = False
    try:
        yield
    finally:
        for action in changed:
            action.required = True
