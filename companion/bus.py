"""Zenoh at the edge: live telemetry out, remote control in, for one companion (or a monitor).

Key expressions (``<vehicle_id>`` defaults to ``rover<sysid>``, e.g. ``rover1``)::

    rover/<vehicle_id>/state     put, one per control cycle (or every N-th: --state-every N)
    rover/<vehicle_id>/status    put, one per life-cycle event
    rover/<vehicle_id>/control   queryable, only with --control-secret FILE

Payloads are UTF-8 JSON objects (readable with any tool, ~600 bytes, ~10 us to encode; a binary
encoding would save bytes the loop does not miss at 20-1000 Hz). Each carries a ``schema`` field
``"pzc-rover/<kind>/<major>"``: a reader must refuse a major it does not know and ignore fields it
does not know (fields are only ever added within a major). Units: metres, radians, seconds;
positions are LOCAL_NED (x north, y east), yaw from north towards east.

``pzc-rover/state/1``::

    {"schema": "pzc-rover/state/1", "vehicle_id": "rover1",
     "seq": 42,                 # tracking-cycle count since the companion started (steps by
                                # N when decimated: a jump larger than "every" is a lost sample)
     "every": 1,                # the decimation N
     "sent_at": 1732368000.123, # companion wall clock (Unix s) at publication
     "vehicle_time": 12.345,    # vehicle clock (time_boot_ms / 1000)
     "mission_time": 3.21,      # mission clock (stands still while paused)
     "pose":      {"x": .., "y": .., "yaw": ..},   # measured (LOCAL_POSITION_NED, ATTITUDE)
     "filtered":  {"x": .., "y": .., "yaw": ..},   # the model-free filter's estimate
     "reference": {"x": .., "y": ..},              # the trajectory at mission_time
     "error":     {"position": .., "yaw": ..},     # |p_ref - p| and yaw of u_p minus yaw_hat
     "setpoint":  {"speed": .., "yaw_rate": .., "ux": .., "uy": ..},   # what was sent
     "mode": "GUIDED", "armed": true}

``pzc-rover/status/1``::

    {"schema": "pzc-rover/status/1", "vehicle_id": "rover1", "seq": 3, "sent_at": ..,
     "kind": "connected" | "tracking" | "paused" | "resumed" | "mission_loaded" | "mission_done"
             | "failsafe" | "pilot_override" | "stopped",
     "reason": "free text", "vehicle_time": 12.3 | null, "detail": {..}}

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
stays as a second factor. :func:`control_request` is the client side.

Publishing never blocks the loop: publishers use ``CongestionControl.DROP`` (a full queue drops
the sample instead of waiting), and the loop's only work is one ``json.dumps`` (~15 us) and one
``put`` that only enqueues (~1 us; Zenoh's own thread writes the socket).
Zenoh's callback threads are not daemon threads: every session is closed on every path out
(:meth:`Bus.close`, :func:`close_all`), or the process never exits.
"""

from __future__ import annotations

import hmac
import json
import math
import os
import queue
import re
import signal
import threading
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .errors import UserError
from .live import events as ev
from .live.events import ControlChannel, LoopRecord, StatusEvent
from .secretfile import read_private

if TYPE_CHECKING:       # loads the cryptography library: only sessions with TLS need it
    from .security.identity import Identity

STATE_SCHEMA = "pzc-rover/state/1"
STATUS_SCHEMA = "pzc-rover/status/1"
REPLY_SCHEMA = "pzc-rover/control-reply/1"
VERBS = ("status", "start", "pause", "resume", "abort", "load-mission")
MAX_MISSION_BYTES = 256 * 1024          # a mission is a few kB; refuse what is not one
CONTROL_TIMEOUT = 1.0                   # s the queryable waits for the loop (a cycle or two)
_VEHICLE_ID = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")   # one key-expression chunk, no wildcards

_sessions: set[Any] = set()             # every session this process opened and has not closed
_sessions_lock = threading.Lock()


def state_key(vehicle_id: str) -> str:
    return f"rover/{vehicle_id}/state"


def status_key(vehicle_id: str) -> str:
    return f"rover/{vehicle_id}/status"


def control_key(vehicle_id: str) -> str:
    return f"rover/{vehicle_id}/control"


# --------------------------------------------------------------------------- options, session

@dataclass(frozen=True)
class BusOptions:
    """What the ``--zenoh-*`` flags say (see :mod:`companion.commands.zenoh_args`)."""

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


def _zerror(exc: Exception) -> str:
    """Zenoh's message without the Rust source location it appends."""
    text = str(exc).strip()
    text = re.sub(r"\s+at /\S+\.rs:\d+\.?", "", text)
    return " ".join(text.split())


def check_vehicle_id(text: str) -> str:
    if not _VEHICLE_ID.match(text):
        raise UserError(f"--vehicle-id {text!r}: use 1-64 letters, digits, '_', '-' or '.' "
                        "(it becomes one chunk of the key rover/<vehicle_id>/...)")
    return text


def make_config(opts: BusOptions, default_mode: str = "peer"):
    """A zenoh.Config from the options: the file (if any), then the flags over it."""
    return prepare(opts, default_mode).config


def prepare(opts: BusOptions, default_mode: str = "peer") -> Prepared:
    """The config (file, then flags over it) and, with mutual TLS, the checked identity."""
    import zenoh
    path = opts.config_file or os.environ.get("ZENOH_CONFIG") or None
    flag = "--zenoh-config" if opts.config_file else "$ZENOH_CONFIG"
    if path:
        if not Path(path).is_file():
            raise UserError(f"{flag} {path}: no such file")
        try:
            config = zenoh.Config.from_file(path)
        except Exception as exc:  # noqa: BLE001  (zenoh raises ZError for every problem)
            raise UserError(f"{flag} {path}: not a valid Zenoh config: {_zerror(exc)}") from None
    else:
        config = zenoh.Config()
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
            raise UserError(f"{what}: {_zerror(exc)}") from None
    identity = _secure(config, opts, f"{flag} {path}" if path else None)
    return Prepared(config, identity)


def _get(config, key: str) -> Any:
    return json.loads(config.get_json(key))


def _put(config, key: str, value: Any, what: str) -> None:
    try:
        config.insert_json5(key, json.dumps(value))
    except Exception as exc:  # noqa: BLE001  (zenoh raises ZError for every problem)
        raise UserError(f"{what}: Zenoh refused {key}: {_zerror(exc)}") from None


def _secure(config, opts: BusOptions, file: str | None) -> Identity | None:
    """Mutual TLS and role access control, from ``--zenoh-tls DIR/NAME`` or from the config
    file's own TLS certificate (the same checks either way); None when neither asks for it.

    Zenoh does the TLS and the access control; this writes its settings, after checking
    what Zenoh would only report as a failed handshake."""
    import zenoh

    from .security import tls
    own = _get(config, tls.TLS_KEY) or {}
    cert = own.get("connect_certificate") or own.get("listen_certificate")
    key = own.get("connect_private_key") or own.get("listen_private_key")
    if opts.tls is None and not (own.get("root_ca_certificate") and cert and key):
        return None
    from .security import acl
    from .security import identity as ids
    if opts.tls is not None:
        me = ids.from_spec(opts.tls, opts.roles)
    else:
        assert cert is not None and key is not None   # all three given: see the return above
        me = ids.load(Path(own["root_ca_certificate"]), Path(cert), Path(key), opts.roles,
                      where=f"{file} (transport/link/tls)", key_flag=f"{file}: key")
    mode = _get(config, "mode") or "peer"
    # Zenoh's default listener (a peer's tcp/[::]:0, a router's tcp/[::]:7447) is in clear:
    # listen only where the flags or the file say.
    if not opts.listen and _get(config, "listen/endpoints") == _get(zenoh.Config(),
                                                                   "listen/endpoints"):
        _put(config, "listen/endpoints", [], "mutual TLS")
    for setting, given, flag in (("listen/endpoints", opts.listen, "--zenoh-listen"),
                                 ("connect/endpoints", opts.connect, "--zenoh-connect")):
        where = flag if given else f"{file or 'Zenoh default'}: {setting}"
        tls.check_endpoints(tls.endpoints_for(_get(config, setting), mode), where)
    _put(config, tls.TLS_KEY, tls.settings(me), "mutual TLS")
    # A file that writes its own access control keeps it (its author chose); else the roles'.
    if not (_get(config, "access_control") or {}).get("enabled"):
        _put(config, "access_control", acl.access_control(me.role, me.name, me.roster),
             "access control")
    return me


def open_session(opts: BusOptions, default_mode: str = "peer", prepared: Prepared | None = None,
                 log: Callable[[str], None] | None = None):
    """Open a Zenoh session (remembered for :func:`close_all`); UserError when it cannot."""
    import zenoh
    prepared = prepared or prepare(opts, default_mode)
    if log is not None and prepared.identity is not None:
        log(prepared.identity.describe())
    try:
        session = zenoh.open(prepared.config)
    except Exception as exc:  # noqa: BLE001
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
        raise UserError(f"cannot open the Zenoh session ({', '.join(where) or 'defaults'}): "
                        f"{_zerror(exc)}") from None
    with _sessions_lock:
        _sessions.add(session)
    return session


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


def read_secret(path: str, flag: str = "--control-secret") -> bytes:
    """The shared control secret; refused when group or others may access the file."""
    # Read a little past the longest sensible secret: enough to strip whitespace.
    secret = read_private(path, flag, "secret", 4096).strip()
    if len(secret) < 8:
        raise UserError(f"{flag} {path}: the secret must be at least 8 bytes")
    return secret


# --------------------------------------------------------------------------- payloads

def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


def state_payload(vehicle_id: str, seq: int, every: int, rec: LoopRecord,
                  sent_at: float) -> dict[str, Any]:
    return {
        "schema": STATE_SCHEMA, "vehicle_id": vehicle_id, "seq": seq, "every": every,
        "sent_at": sent_at, "vehicle_time": rec.vehicle_time, "mission_time": rec.mission_time,
        "pose": {"x": rec.x, "y": rec.y, "yaw": rec.yaw},
        "filtered": {"x": rec.x_hat, "y": rec.y_hat, "yaw": rec.yaw_hat},
        "reference": {"x": rec.x_ref, "y": rec.y_ref},
        "error": {"position": rec.err_pos, "yaw": rec.err_yaw},
        "setpoint": {"speed": rec.speed_cmd, "yaw_rate": rec.yaw_rate_cmd,
                     "ux": rec.ux, "uy": rec.uy},
        "mode": rec.mode, "armed": rec.armed,
    }


def status_payload(vehicle_id: str, seq: int, event: StatusEvent,
                   sent_at: float) -> dict[str, Any]:
    return {"schema": STATUS_SCHEMA, "vehicle_id": vehicle_id, "seq": seq, "sent_at": sent_at,
            "kind": event.kind, "reason": event.reason, "vehicle_time": event.vehicle_time,
            "detail": event.detail}


def encode(payload: dict[str, Any]) -> bytes:
    try:
        return json.dumps(payload, separators=(",", ":"), allow_nan=False).encode()
    except ValueError:
        # A NaN from the filter must not make the JSON unreadable: null it (rare path).
        return json.dumps(_sanitize(payload), separators=(",", ":")).encode()


def _sanitize(obj: Any) -> Any:
    if isinstance(obj, float):
        return _finite(obj)
    if isinstance(obj, dict):
        return {k: _sanitize(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_sanitize(v) for v in obj]
    return obj


def decode(data: bytes, kind: str | None = None) -> dict[str, Any]:
    """Parse a payload; ValueError if it is not one of ours (or not of ``kind``, major 1)."""
    obj = json.loads(data)
    if not isinstance(obj, dict) or not isinstance(obj.get("schema"), str):
        raise ValueError("no schema field")
    parts = obj["schema"].split("/")
    if len(parts) != 3 or parts[0] != "pzc-rover" or parts[2] != "1":
        raise ValueError(f"unknown schema {obj['schema']!r}")
    if kind is not None and parts[1] != kind:
        raise ValueError(f"expected a {kind} payload, got {obj['schema']!r}")
    return obj


# --------------------------------------------------------------------------- the vehicle side

class Bus:
    """One companion's Zenoh presence: a :class:`~companion.live.events.Sink` for the runner that
    publishes state and status, plus (with a secret) the control queryable feeding ``control``.

    The key expressions need the vehicle id, which defaults to ``rover<sysid>``: publishers and
    the queryable are declared at the runner's first event (``connected``, which names the
    sysid), before anything else is published.
    """

    def __init__(self, session, opts: BusOptions, secret: bytes | None = None,
                 log: Callable[[str], None] = lambda text: None):
        self.session, self.opts, self.log = session, opts, log
        self.secret = secret
        self.control: ControlChannel | None = ControlChannel() if secret is not None else None
        self.vehicle_id: str | None = opts.vehicle_id
        self.every = max(1, int(opts.state_every))
        self._state_pub: Any = None       # zenoh.Publisher, declared with the first status
        self._status_pub: Any = None
        self._queryable = None
        self._worker: threading.Thread | None = None
        self._requests: queue.Queue = queue.Queue()
        self._cycle = 0
        self._status_seq = 0
        self.published = 0
        self.refused = 0
        self._next_refusal_log = 0.0
        self._closed = False

    # --- Sink ------------------------------------------------------------------------------
    def record(self, rec: LoopRecord) -> None:
        self._cycle += 1
        if self._state_pub is None or (self._cycle - 1) % self.every:
            return
        assert self.vehicle_id is not None   # _declare named it with the publishers
        self._state_pub.put(encode(state_payload(self.vehicle_id, self._cycle, self.every, rec,
                                                 time.time())))
        self.published += 1

    def status(self, event: StatusEvent) -> None:
        if self._state_pub is None:
            if self._closed:
                return
            self._declare(event)
        self._status_seq += 1
        assert self.vehicle_id is not None   # _declare named it
        self._status_pub.put(encode(status_payload(self.vehicle_id, self._status_seq, event,
                                                   time.time())))

    def close(self) -> None:
        """Undeclare everything (the runner calls this at its end; the owner closes the session)."""
        if self._closed:
            return
        self._closed = True
        if self._queryable is not None:
            self._undeclare(self._queryable)
            self._requests.put(None)
            if self._worker is not None:
                self._worker.join(CONTROL_TIMEOUT + 0.2)
        for pub in (self._state_pub, self._status_pub):
            if pub is not None:
                self._undeclare(pub)

    @staticmethod
    def _undeclare(entity) -> None:
        try:
            entity.undeclare()
        except Exception:  # noqa: BLE001  (the session may be closed already)
            pass

    def _declare(self, event: StatusEvent) -> None:
        import zenoh
        if self.vehicle_id is None:
            sysid = event.detail.get("sysid", 0) if event.kind == ev.CONNECTED else 0
            self.vehicle_id = f"rover{sysid}"
        vid = self.vehicle_id
        json_enc = zenoh.Encoding.APPLICATION_JSON
        # DROP: a congested link loses samples instead of stalling the control loop. Not
        # express: put only enqueues (~1 us; Zenoh's own thread writes the socket), where an
        # express put writes it in the caller (~35 us), for the same latency (measured:
        # benchmarks/bench_zenoh.py).
        self._state_pub = self.session.declare_publisher(
            state_key(vid), encoding=json_enc, congestion_control=zenoh.CongestionControl.DROP,
            priority=zenoh.Priority.DATA)
        # Life-cycle events go on a higher priority (its own queue) so a flood of state
        # samples cannot crowd them out, and express so the last one ("stopped") is on the
        # wire before the session closes.
        self._status_pub = self.session.declare_publisher(
            status_key(vid), encoding=json_enc, congestion_control=zenoh.CongestionControl.DROP,
            priority=zenoh.Priority.DATA_HIGH, express=True)
        what = f"publishing {state_key(vid)} (every {self.every} cycle(s)) and {status_key(vid)}"
        if self.control is not None:
            self._worker = threading.Thread(target=self._serve, name="zenoh-control",
                                            daemon=True)
            self._worker.start()
            self._queryable = self.session.declare_queryable(control_key(vid), self._on_query)
            what += f"; control on {control_key(vid)}"
        self.log(what)

    # --- control queryable ---------------------------------------------------------------------
    def _on_query(self, query) -> None:
        """Zenoh's thread: refuse what is malformed or unauthorised at once, queue the rest."""
        try:
            verb, payload, problem = self._check_query(query)
        except Exception as exc:  # noqa: BLE001  (never let a bad query kill the callback)
            verb, payload, problem = "", "", f"malformed request: {type(exc).__name__}"
        if problem is not None:
            self.refused += 1
            _reply(query, False, verb, problem)
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
        if self.secret is None or not hmac.compare_digest(given, self.secret):
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
                _reply(query, False, verb, "the companion is stopping")
                continue
            # A remote operator sends mission text, never a file name on this machine.
            assert self.control is not None   # the worker runs only with a control channel
            ok, message = self.control.submit(verb, payload, timeout=CONTROL_TIMEOUT,
                                              allow_path=False)
            extra = {}
            if ok and verb == "status":
                try:
                    extra["status"] = json.loads(message)
                    message = extra["status"].get("state", "")
                except ValueError:
                    pass
            _reply(query, ok, verb, message, extra)
            if verb != "status":
                self.log(f"control: {verb}: {'done' if ok else 'refused'}: {message}")
        # Anything still queued gets an answer too, not a silent timeout.
        while True:
            try:
                item = self._requests.get_nowait()
            except queue.Empty:
                return
            if item is not None:
                _reply(item[0], False, item[1], "the companion is stopping")


def _reply(query, ok: bool, verb: str, message: str, extra: dict | None = None) -> None:
    body = encode({"schema": REPLY_SCHEMA, "ok": ok, "verb": verb, "message": message,
                   **(extra or {})})
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


def open_bus(opts: BusOptions, log: Callable[[str], None] = lambda text: None) -> Bus | None:
    """The companion's bus from the options (None with --no-zenoh); UserError on bad input.

    The secret is read before the session opens, so a bad file costs nothing to refuse."""
    if not opts.enabled:
        return None
    if opts.vehicle_id is not None:
        check_vehicle_id(opts.vehicle_id)
    if opts.state_every < 1:
        raise UserError(f"--state-every {opts.state_every}: must be >= 1")
    secret = read_secret(opts.control_secret) if opts.control_secret else None
    prepared = prepare(opts)
    me = prepared.identity
    if me is not None:
        # The router lets a rover publish only under its certificate's name: that is its id.
        if opts.vehicle_id is not None and opts.vehicle_id != me.name:
            raise UserError(f"--vehicle-id {opts.vehicle_id}: the certificate {me.cert} is "
                            f"{me.name}'s, and a rover publishes only under its own name "
                            "(drop --vehicle-id, or issue a certificate for that name)")
        opts = replace(opts, vehicle_id=me.name)
    session = open_session(opts, prepared=prepared, log=log)
    return Bus(session, opts, secret, log)


def shut(bus: Bus | None) -> None:
    """Every path out of a command: undeclare, close the session, and any other left open."""
    if bus is not None:
        bus.close()
        close_session(bus.session)
    close_all()


# --------------------------------------------------------------------------- the client side

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
