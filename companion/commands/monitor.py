"""``companion monitor``: every rover on the Zenoh bus, live in the terminal (or one snapshot).

Subscribes to ``rover/*/state`` and ``rover/*/status`` and keeps, per vehicle: mode, armed, the
last life-cycle event, speed (from successive poses on the vehicle's clock), tracking error,
age of the last message, message counts, lost samples (gaps in ``seq``) and the longest gap
between two state messages as received here. ``--record FILE`` writes every message as one JSON
line ``{"rx": unix time received, "key": key expression, "payload": {...}}``. ``--once --json``
listens for ``--wait`` seconds (SIGTERM / Ctrl-C ends the wait early), prints one
``pzc-rover/monitor/1`` snapshot and exits.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from dataclasses import asdict, dataclass
from typing import Any, TextIO

from ..app.arguments import add_zenoh_arguments, positive
from ..app.options import bus_options
from ..errors import UserError

SNAPSHOT_SCHEMA = "pzc-rover/monitor/1"


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "monitor", help="live view of every rover on the Zenoh bus",
        description=__doc__.split("\n\n", 1)[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--once", action="store_true",
                   help="listen for --wait seconds, print one snapshot of all vehicles, exit")
    p.add_argument("--json", action="store_true", help="snapshots as JSON (one object a line)")
    p.add_argument("--wait", type=positive, default=2.0, metavar="S",
                   help="with --once: how long to listen before the snapshot (default 2)")
    p.add_argument("--duration", type=positive, metavar="S",
                   help="exit after S seconds (default: until Ctrl-C / SIGTERM)")
    p.add_argument("--refresh", type=positive, default=0.5, metavar="S",
                   help="redraw every S seconds (default 0.5)")
    p.add_argument("--record", metavar="FILE", help="save every message as JSON lines")
    p.add_argument("--key", default="rover/*", metavar="KEYEXPR",
                   help="vehicles to watch (default rover/*)")
    # An operator watches what it steers: its certificate may monitor too.
    add_zenoh_arguments(p, vehicle=False, roles=("monitor", "operator"))
    p.set_defaults(func=run)


@dataclass
class Seen:
    vehicle_id: str
    mode: str = ""
    armed: bool | None = None
    state: str = ""                 # the last life-cycle event kind
    reason: str = ""
    speed: float | None = None      # m/s, from successive poses
    err_pos: float | None = None
    mission_time: float | None = None
    last_rx: float = 0.0            # monotonic, this process
    state_msgs: int = 0
    status_msgs: int = 0
    lost: int = 0                   # state samples missing by seq
    bad: int = 0                    # payloads that were not ours
    max_gap_ms: float = 0.0         # longest silence between two state messages
    _prev: tuple[float, float, float] | None = None   # vehicle time, x, y
    _prev_seq: int | None = None
    _prev_rx: float | None = None

    def view(self, now: float) -> dict[str, Any]:
        d = {k: v for k, v in asdict(self).items() if not k.startswith("_")}
        d["age_s"] = round(now - self.last_rx, 3) if self.last_rx else None
        d.pop("last_rx")
        d["max_gap_ms"] = round(self.max_gap_ms, 1)
        return d


class Fleet:
    """What the subscriber callbacks (Zenoh's threads) update and the display reads."""

    def __init__(self, record: TextIO | None = None):
        self.lock = threading.Lock()
        self.vehicles: dict[str, Seen] = {}
        self.record = record
        self.bad = 0
        self.frozen = False     # after the last snapshot: the record holds what it counted

    def on_sample(self, sample) -> None:
        from ..bus.codec import NOTICES, decode
        rx_wall, rx = time.time(), time.monotonic()
        key = str(sample.key_expr)
        parts = key.split("/")
        data = sample.payload.to_bytes()
        with self.lock:
            if self.frozen:
                return
            if len(parts) != 3:
                self.bad += 1
                return
            vid, kind = parts[1], parts[2]
            v = self.vehicles.get(vid) or self.vehicles.setdefault(vid, Seen(vid))
            try:
                msg = decode(data, kind)
            except ValueError:
                v.bad += 1
                return
            v.last_rx = rx
            if kind == "state":
                self._state(v, msg, rx)
            else:
                v.status_msgs += 1
                if msg.get("kind") not in NOTICES:
                    v.state, v.reason = msg.get("kind", ""), msg.get("reason", "")
            if self.record is not None:
                self.record.write(json.dumps({"rx": rx_wall, "key": key, "payload": msg}) + "\n")

    @staticmethod
    def _state(v: Seen, msg: dict, rx: float) -> None:
        v.state_msgs += 1
        if v._prev_rx is not None:
            v.max_gap_ms = max(v.max_gap_ms, (rx - v._prev_rx) * 1e3)
        v._prev_rx = rx
        seq, every = msg.get("seq"), msg.get("every", 1) or 1
        if isinstance(seq, int) and v._prev_seq is not None and seq > v._prev_seq + every:
            v.lost += (seq - v._prev_seq) // every - 1
        v._prev_seq = seq if isinstance(seq, int) else None
        v.mode, v.armed = msg.get("mode", ""), msg.get("armed")
        v.err_pos = (msg.get("error") or {}).get("position")
        v.mission_time = msg.get("mission_time")
        t, pose = msg.get("vehicle_time"), msg.get("pose") or {}
        x, y = pose.get("x"), pose.get("y")
        if isinstance(t, (int, float)) and isinstance(x, (int, float)) and isinstance(y, (int, float)):
            if v._prev is not None and t > v._prev[0]:
                v.speed = math.hypot(x - v._prev[1], y - v._prev[2]) / (t - v._prev[0])
            v._prev = (t, x, y)
        if v.state in ("", "connected"):
            v.state = "tracking"

    def snapshot(self, last: bool = False) -> dict[str, Any]:
        """The vehicles as seen now; ``last`` stops counting and recording here, so that the
        final snapshot and ``--record`` describe the same messages (Zenoh's threads may deliver
        more before the session closes)."""
        now = time.monotonic()
        with self.lock:
            vehicles = [self.vehicles[k].view(now) for k in sorted(self.vehicles)]
            self.frozen = self.frozen or last
        return {"schema": SNAPSHOT_SCHEMA, "time": time.time(), "vehicles": vehicles}


def table(snap: dict[str, Any]) -> str:
    rows = [f"{'vehicle':<14} {'mode':<9} {'arm':<4} {'state':<14} {'speed':>7} "
            f"{'error':>7} {'age':>7} {'msgs':>7} {'lost':>5} {'gap':>8}"]
    for v in snap["vehicles"]:
        def num(x, unit="", fmt="{:.2f}"):
            return "-" if x is None else fmt.format(x) + unit
        rows.append(f"{v['vehicle_id']:<14} {v['mode'] or '-':<9} "
                    f"{'yes' if v['armed'] else 'no' if v['armed'] is False else '-':<4} "
                    f"{v['state'] or '-':<14} {num(v['speed']):>7} {num(v['err_pos']):>7} "
                    f"{num(v['age_s'], 's', '{:.1f}'):>7} {v['state_msgs']:>7} {v['lost']:>5} "
                    f"{num(v['max_gap_ms'], 'ms', '{:.0f}'):>8}")
    if not snap["vehicles"]:
        rows.append("(no vehicle seen yet)")
    return "\n".join(rows)


def run(args) -> int:
    import zenoh  # noqa: F401  (fail here, not inside a callback, if it is missing)

    from ..bus.session import session_until_signal

    record = None
    if args.record:
        try:
            record = open(args.record, "w", encoding="utf-8")
        except OSError as exc:
            raise UserError(f"--record {args.record}: cannot write: {exc.strerror}") from None
    fleet = Fleet(record)
    try:
        with session_until_signal(bus_options(args)) as (session, stop):
            for kind in ("state", "status"):
                session.declare_subscriber(f"{args.key}/{kind}", fleet.on_sample)
            t0 = time.monotonic()
            end = t0 + (args.wait if args.once else (args.duration or math.inf))
            tty = sys.stdout.isatty() and not args.json
            while not stop.is_set():
                left = end - time.monotonic()
                if left <= 0:
                    break
                if stop.wait(min(args.refresh, left)) or args.once:
                    continue
                _show(fleet.snapshot(), args.json, tty)
            snap = fleet.snapshot(last=True)
    finally:
        with fleet.lock:        # no callback writes to the file once it is closed
            fleet.frozen = True
            if record is not None:
                record.close()
    if args.once:
        _show(snap, args.json, False)
    return 0


def _show(snap: dict[str, Any], as_json: bool, tty: bool) -> None:
    if as_json:
        print(json.dumps(snap), flush=True)
        return
    text = table(snap)
    if tty:
        sys.stdout.write("\x1b[H\x1b[2J")      # home + clear: redraw in place
    print(text + ("" if tty else "\n"), flush=True)
