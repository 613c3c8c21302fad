"""A session's Zenoh configuration from the ``--zenoh-*`` flags: the file (if any), the flags
over it; and the small helpers that read and write Zenoh's config and its errors."""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import UserError

if TYPE_CHECKING:       # loads the cryptography library: only sessions with TLS need it
    from ..security.identity import Identity


@dataclass(frozen=True)
class BusOptions:
    """What the ``--zenoh-*`` flags say (see :mod:`companion.commands.arguments`)."""

    enabled: bool = True
    mode: str | None = None              # peer (default) / client / router
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    config_file: str | None = None       # --zenoh-config, else $ZENOH_CONFIG
    scouting: bool | None = None         # multicast scouting; None: Zenoh's default
    vehicle_id: str | None = None        # None: rover<sysid>
    state_every: int = 1
    control_secret: str | None = None    # path; None: no control queryable
    tls: str | None = None               # --zenoh-tls DIR/NAME: mutual TLS + access control
    roles: tuple[str, ...] = ()          # certificate roles this command accepts (() any)


@dataclass(frozen=True)
class Prepared:
    """A session's config, checked, and the fleet identity it carries (None: no TLS)."""

    config: Any                          # zenoh.Config
    identity: Identity | None = None
    note: str | None = None              # a line for the log: what was chosen for the user


def zerror(exc: Exception) -> str:
    """Zenoh's message without the Rust source location it appends."""
    text = str(exc).strip()
    text = re.sub(r"\s+at /\S+\.rs:\d+\.?", "", text)
    return " ".join(text.split())


def get(config, key: str) -> Any:
    """The value of ``key`` in a zenoh.Config, as Python."""
    return json.loads(config.get_json(key))


def put(config, key: str, value: Any, what: str) -> None:
    """Set ``key``; a UserError naming ``what`` asked for it when Zenoh refuses the value."""
    try:
        config.insert_json5(key, json.dumps(value))
    except Exception as exc:  # noqa: BLE001  (zenoh raises ZError for every problem)
        raise UserError(f"{what}: Zenoh refused {key}: {zerror(exc)}") from None


def file_flag(opts: BusOptions) -> tuple[str | None, str]:
    """The config file that applies (``--zenoh-config``, else ``$ZENOH_CONFIG``; None: neither)
    and the flag to name in messages about it."""
    path = opts.config_file or os.environ.get("ZENOH_CONFIG") or None
    return path, ("--zenoh-config" if opts.config_file else "$ZENOH_CONFIG")


def from_flags(opts: BusOptions, default_mode: str = "peer") -> tuple[Any, bool]:
    """A zenoh.Config (the file, if any, then the flags over it) and whether a flag or the file
    chose the mode; UserError for what Zenoh refuses."""
    import zenoh
    path, flag = file_flag(opts)
    if path:
        if not Path(path).is_file():
            raise UserError(f"{flag} {path}: no such file")
        try:
            config = zenoh.Config.from_file(path)
        except Exception as exc:  # noqa: BLE001  (zenoh raises ZError for every problem)
            raise UserError(f"{flag} {path}: not a valid Zenoh config: {zerror(exc)}") from None
    else:
        config = zenoh.Config()
    mode_chosen = opts.mode is not None or get(config, "mode") is not None
    mode = opts.mode or (None if path else default_mode)
    settings: list[tuple[str, str, str]] = []
    if mode:
        settings.append(("mode", json.dumps(mode), f"mode {mode}"))
    if opts.scouting is not None:
        settings.append(("scouting/multicast/enabled", json.dumps(opts.scouting),
                         "--zenoh-scouting"))
    if opts.listen:
        settings.append(("listen/endpoints", json.dumps(list(opts.listen)),
                         "--zenoh-listen " + " ".join(opts.listen)))
    if opts.connect:
        settings.append(("connect/endpoints", json.dumps(list(opts.connect)),
                         "--zenoh-connect " + " ".join(opts.connect)))
    for key, value, what in settings:
        try:
            config.insert_json5(key, value)
        except Exception as exc:  # noqa: BLE001
            raise UserError(f"{what}: {zerror(exc)}") from None
    return config, mode_chosen
