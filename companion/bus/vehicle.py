"""A companion's Zenoh presence: :class:`Bus`, the runner's sink that publishes state and status,
with (given a secret) the control queryable; :func:`open_bus` makes it from the flags and
:func:`shut` ends it on every path out.

Publishing never blocks the loop: publishers use ``CongestionControl.DROP`` (a full queue drops
the sample instead of waiting), and the loop's only work is one ``json.dumps`` (~15 us) and one
``put`` that only enqueues (~1 us; Zenoh's own thread writes the socket).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from ..errors import UserError
from ..live import events as ev
from ..live.events import ControlChannel, LoopRecord, StatusEvent
from .codec import encode, state_payload, status_payload
from .config import BusOptions
from .control import ControlQueryable, read_secret
from .keys import check_vehicle_id, control_key, state_key, status_key
from .session import close_all, close_session, open_session, prepare


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
        self._queryable: ControlQueryable | None = None
        self._cycle = 0
        self._status_seq = 0
        self.published = 0
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
            self._queryable.close()
        for pub in (self._state_pub, self._status_pub):
            if pub is not None:
                try:
                    pub.undeclare()
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
            assert self.secret is not None   # a control channel exists only with a secret
            self._queryable = ControlQueryable(self.session, vid, self.secret, self.control,
                                               self.log)
            what += f"; control on {control_key(vid)}"
        self.log(what)


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
