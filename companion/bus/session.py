"""Opening and closing Zenoh sessions, and the registry of those still open.

Zenoh's callback threads are not daemon threads: every session is closed on every path out
(:func:`close_session`, :func:`close_all`, :func:`session_until_signal`), or the process never
exits. The registry is this process's set of open sessions, for :func:`close_all`.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from contextlib import contextmanager
from typing import Any

from ..errors import UserError
from .config import BusOptions, Prepared, file_flag, from_flags, get, zerror
from .tls import secure

_sessions: set[Any] = set()             # every session this process opened and has not closed
_sessions_lock = threading.Lock()


def prepare(opts: BusOptions, default_mode: str = "peer") -> Prepared:
    """The config (file, then flags over it) and, with mutual TLS, the checked identity."""
    config, mode_chosen = from_flags(opts, default_mode)
    path, flag = file_flag(opts)
    before = get(config, "mode")
    identity = secure(config, opts, f"{flag} {path}" if path else None, mode_chosen)
    note = None
    if get(config, "mode") != before:
        note = (f"mode client over mutual TLS (nowhere to listen, so peers could not reach it): "
                f"everything through {' '.join(opts.connect) or 'the connect endpoints'}")
    return Prepared(config, identity, note)


def open_session(opts: BusOptions, default_mode: str = "peer", prepared: Prepared | None = None,
                 log: Callable[[str], None] | None = None):
    """Open a Zenoh session (remembered for :func:`close_all`); UserError when it cannot."""
    import zenoh
    prepared = prepared or prepare(opts, default_mode)
    if log is not None and prepared.identity is not None:
        log(prepared.identity.describe())
    if log is not None and prepared.note is not None:
        log(prepared.note)
    try:
        session = zenoh.open(prepared.config)
    except Exception as exc:  # noqa: BLE001
        raise UserError(f"cannot open the Zenoh session ({_where(opts, prepared)}): "
                        f"{zerror(exc)}") from None
    with _sessions_lock:
        _sessions.add(session)
    return session


def _where(opts: BusOptions, prepared: Prepared) -> str:
    """What the session was asked to do, for the message saying it could not."""
    where = []
    if opts.connect:
        where.append("--zenoh-connect " + " ".join(opts.connect))
    if opts.listen:
        where.append("--zenoh-listen " + " ".join(opts.listen))
    if opts.config_file:
        where.append(f"--zenoh-config {opts.config_file}")
    if prepared.identity is not None:
        where.append(f"as {prepared.identity.role} {prepared.identity.name!r} over mutual "
                     "TLS: is the peer's certificate from the same CA, and named for the "
                     "host dialled?")
    return ", ".join(where) or "defaults"


def close_session(session) -> None:
    with _sessions_lock:
        _sessions.discard(session)
    try:
        session.close()
    except Exception:  # noqa: BLE001  (closing twice, or after a failed open)
        pass


def close_all() -> None:
    """Close every session still open (the last line of defence against the exit hang)."""
    with _sessions_lock:
        sessions = list(_sessions)
    for session in sessions:
        close_session(session)


@contextmanager
def session_until_signal(opts: BusOptions, default_mode: str = "peer",
                         log: Callable[[str], None] | None = None):
    """A session and an Event that SIGTERM / SIGINT set, for processes that serve until told.

    On every way out the session closes first (Zenoh's callback threads would keep the process
    alive), then every other session, then the previous signal handlers come back.
    """
    stop = threading.Event()
    old = {s: signal.signal(s, lambda signum, frame: stop.set())
           for s in (signal.SIGTERM, signal.SIGINT)}
    session = None
    try:
        session = open_session(opts, default_mode=default_mode, log=log)
        yield session, stop
    finally:
        if session is not None:
            close_session(session)
        close_all()
        for s, h in old.items():
            signal.signal(s, h)
