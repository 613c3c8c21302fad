"""The control queryable a companion serves on ``rover/<id>/control`` (with ``--control-secret``).

Control request (``session.get``): selector ``rover/<id>/control?verb=VERB``, the shared secret
as the query's *attachment*, and for ``load-mission`` the mission's TOML text as the payload
(checked exactly as a mission file is). Verbs: ``status``, ``start``, ``pause``, ``resume``,
``abort`` (zero setpoint and HOLD now), ``load-mission``. The one reply is a
``pzc-rover/control-reply/1`` object ``{"ok", "verb", "message"}`` (``status`` adds
``"status": {..}``): a normal reply when the loop did it, an *error* reply (``reply_err``) for a
refusal (no or wrong secret, unknown verb, bad payload, or the loop said no), which changes
nothing. Over plain TCP the secret travels in clear; with ``--zenoh-tls DIR/NAME`` every link
is mutual TLS and Zenoh's access control enforces the certificate's role (only operators may
query, a rover publishes only under its own name; :mod:`companion.security`), and the secret
stays as a second factor. :mod:`companion.bus.control_client` is the client side.
"""

from __future__ import annotations

import hmac
import json
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

from ..errors import UserError
from ..live.events import ControlChannel
from ..secretfile import read_private
from .codec import encode, reply_payload
from .keys import control_key

VERBS = ("status", "start", "pause", "resume", "abort", "load-mission")
MAX_MISSION_BYTES = 256 * 1024          # a mission is a few kB; refuse what is not one
CONTROL_TIMEOUT = 1.0                   # s the queryable waits for the loop (a cycle or two)


def read_secret(path: str, flag: str = "--control-secret") -> bytes:
    """The shared control secret; refused when group or others may access the file."""
    # Read a little past the longest sensible secret: enough to strip whitespace.
    secret = read_private(path, flag, "secret", 4096).strip()
    if len(secret) < 8:
        raise UserError(f"{flag} {path}: the secret must be at least 8 bytes")
    return secret


class ControlQueryable:
    """``rover/<id>/control`` on a session: checks each query on Zenoh's thread (refusing what
    is malformed or unauthorised at once) and hands the rest to a worker thread, which asks
    the loop through ``channel`` and replies."""

    def __init__(self, session, vehicle_id: str, secret: bytes, channel: ControlChannel,
                 log: Callable[[str], None]):
        self.secret, self.channel, self.log = secret, channel, log
        self.refused = 0
        self._next_refusal_log = 0.0
        self._closed = False
        self._requests: queue.Queue = queue.Queue()
        self._worker = threading.Thread(target=self._serve, name="zenoh-control", daemon=True)
        self._worker.start()
        self._queryable = session.declare_queryable(control_key(vehicle_id), self._on_query)

    def close(self) -> None:
        """Undeclare, then answer whatever is still queued (the worker says it is stopping)."""
        self._closed = True
        try:
            self._queryable.undeclare()
        except Exception:  # noqa: BLE001  (the session may be closed already)
            pass
        self._requests.put(None)
        self._worker.join(CONTROL_TIMEOUT + 0.2)

    def _on_query(self, query) -> None:
        """Zenoh's thread: refuse what is malformed or unauthorised at once, queue the rest."""
        try:
            verb, payload, problem = self._check_query(query)
        except Exception as exc:  # noqa: BLE001  (never let a bad query kill the callback)
            verb, payload, problem = "", "", f"malformed request: {type(exc).__name__}"
        if problem is not None:
            self.refused += 1
            reply(query, False, verb, problem)
            now = time.monotonic()
            if now >= self._next_refusal_log:     # at most a line a second, even under a flood
                self._next_refusal_log = now + 1.0
                self.log(f"control: {problem} ({self.refused} refused so far)")
            return
        # The loop answers within a cycle; waiting for it here would stall Zenoh's thread.
        self._requests.put((query, verb, payload))

    def _check_query(self, query) -> tuple[str, str, str | None]:
        verb = query.parameters.get("verb") or ""
        attachment = query.attachment
        given = attachment.to_bytes() if attachment is not None else b""
        if not given:
            return verb, "", "refused: no secret (send it as the query's attachment)"
        if not hmac.compare_digest(given, self.secret):
            return verb, "", "refused: wrong secret"
        if verb not in VERBS:
            return verb, "", (f"unknown verb {verb!r}: use ?verb= one of {', '.join(VERBS)}"
                              if verb else "no verb: use ?verb= one of " + ", ".join(VERBS))
        data = query.payload.to_bytes() if query.payload is not None else b""
        if verb != "load-mission":
            return verb, "", (f"{verb} takes no payload" if data.strip() else None)
        if not data.strip():
            return verb, "", "load-mission needs the mission's TOML text as the payload"
        if len(data) > MAX_MISSION_BYTES:
            return verb, "", f"mission text too long ({len(data)} bytes > {MAX_MISSION_BYTES})"
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            return verb, "", "mission text is not UTF-8"
        return verb, text, None

    def _serve(self) -> None:
        while True:
            item = self._requests.get()
            if item is None:
                break
            query, verb, payload = item
            if self._closed:
                reply(query, False, verb, "the companion is stopping")
                continue
            # A remote operator sends mission text, never a file name on this machine.
            ok, message = self.channel.submit(verb, payload, timeout=CONTROL_TIMEOUT,
                                              allow_path=False)
            extra = {}
            if ok and verb == "status":
                try:
                    extra["status"] = json.loads(message)
                    message = extra["status"].get("state", "")
                except ValueError:
                    pass
            reply(query, ok, verb, message, extra)
            if verb != "status":
                self.log(f"control: {verb}: {'done' if ok else 'refused'}: {message}")
        # Anything still queued gets an answer too, not a silent timeout.
        while True:
            try:
                item = self._requests.get_nowait()
            except queue.Empty:
                return
            if item is not None:
                reply(item[0], False, item[1], "the companion is stopping")


def reply(query, ok: bool, verb: str, message: str, extra: dict[str, Any] | None = None) -> None:
    """The one reply to ``query``: a normal reply when ``ok``, else an error reply."""
    body = encode(reply_payload(ok, verb, message, extra))
    try:
        if ok:
            query.reply(query.key_expr, body)
        else:
            query.reply_err(body)
    except Exception:  # noqa: BLE001  (the requester gave up, or the session is closing)
        pass
    finally:
        try:
            query.drop()       # sends the final reply now rather than at garbage collection
        except Exception:  # noqa: BLE001
            pass
