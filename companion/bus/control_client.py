"""The operator's side of ``rover/<id>/control``: one request, its one reply
(the protocol: :mod:`companion.bus.control`)."""

from __future__ import annotations

import time
from typing import Any

from .codec import decode
from .keys import control_key


def control_request(session, vehicle_id: str, verb: str, secret: bytes | str | None = None,
                    payload: bytes | str | None = None, timeout: float = 5.0) -> dict[str, Any]:
    """Send one control request; the decoded reply, ``ok`` False for an error reply, or
    ``{"ok": False, "message": "no reply ..."}`` when nothing answered."""
    kwargs: dict[str, Any] = {}
    if secret is not None:
        kwargs["attachment"] = secret
    if payload is not None:
        kwargs["payload"] = payload
    selector = control_key(vehicle_id) + (f"?verb={verb}" if verb else "")
    deadline = time.monotonic() + timeout
    while (left := deadline - time.monotonic()) > 0:
        asked = time.monotonic()
        for reply in session.get(selector, timeout=left, **kwargs):
            if reply.ok is not None:
                return _reply_body(reply.ok.payload.to_bytes(), True)
            return _reply_body(reply.err.payload.to_bytes(), False)
        if time.monotonic() - asked > 0.5 * left:
            break       # something took the query but did not answer: never send it twice
        # No queryable matched (yet): a session that just opened may still be learning its
        # routes (peers find each other by gossip after the open returns). Ask again shortly.
        time.sleep(0.1)
    return {"ok": False, "verb": verb,
            "message": f"no reply from {control_key(vehicle_id)} within {timeout:g} s "
                       "(control not enabled, or the vehicle not reachable)"}


def _reply_body(data: bytes, ok: bool) -> dict[str, Any]:
    try:
        body = decode(data, "control-reply")
    except ValueError:
        body = {"message": data.decode(errors="replace")}
    body["ok"] = bool(body.get("ok", ok)) and ok
    return body
