"""One self-contained HTML page per flight or calibration: what to send someone.

A flight is the logs that share a stem in LOGDIR (``<stem>.csv`` preferred, else ``.tlog``;
:mod:`companion.logs.logread` reads them) and the record ``<stem>.json`` the flight wrote when
it ended (``companion.app.flight.write_record``: command line, vehicle file, gains, limits,
result). A calibration is a folder with ``vehicle.toml`` and ``gains.toml`` (``companion
calibrate --out DIR``). The page holds the paper's metrics (f_cost, steady RMS, max error:
:meth:`~companion.logs.logread.Flight.metrics`), the figures of :mod:`companion.logs.plot`
inlined as base64 PNG, the gains and limits, the vehicle file's text, the command line and the
events; no script, no link out: it opens offline, and prints.
"""

from __future__ import annotations

import base64
import html
import json
import shlex
import tempfile
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..errors import UserError
from .logread import read
from .plot import plot_flight

RECORD_SCHEMA = "pzc-rover/flight-record/1"
STYLE = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
h1{font-size:1.5em}h2{font-size:1.15em;border-bottom:1px solid #ccc;padding-bottom:.2em}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:.25em .6em;
text-align:left;font-size:.92em}th{background:#f2f2f2}pre{background:#f6f6f6;padding:.6em;
overflow-x:auto;font-size:.85em}img{max-width:100%;display:block;margin:.6em 0}
.warn{color:#b00}.dim{color:#777}"""


@dataclass
class Item:
    """One page: a flight (its log, maybe its record) or a calibration folder."""

    kind: str                       # "flight" or "calibration"
    name: str
    log: Path | None = None
    record: dict[str, Any] | None = None
    files: dict[str, str] = field(default_factory=dict)     # calibration: name -> text
    flights: list[Item] = field(default_factory=list)        # calibration: its flights


def find(logdir: str) -> list[Item]:
    """Every flight (and the calibration, if the folder is one) in LOGDIR, or the one log."""
    root = Path(logdir)
    if not root.exists():
        raise UserError(f"LOGDIR {logdir}: no such file or folder")
    if root.is_file():
        return [_flight(root)]
    stems: dict[str, Path] = {}
    for p in sorted(root.rglob("*")):
        if p.suffix.lower() in (".csv", ".tlog"):
            key = str(p.with_suffix(""))
            if key not in stems or p.suffix.lower() == ".csv":
                stems[key] = p
    flights = [_flight(p) for p in stems.values()]
    if (root / "vehicle.toml").is_file() and (root / "gains.toml").is_file():
        files = {name: (root / name).read_text(encoding="utf-8", errors="replace")
                 for name in ("vehicle.toml", "gains.toml") if (root / name).is_file()}
        return [Item("calibration", root.name or str(root), files=files, flights=flights)]
    if not flights:
        raise UserError(f"LOGDIR {logdir}: no flight log (.csv or .tlog) in it")
    return flights


def _flight(log: Path) -> Item:
    record = None
    side = log.with_suffix(".json")
    if side.is_file():
        try:
            obj = json.loads(side.read_text(encoding="utf-8"))
            record = obj if isinstance(obj, dict) and obj.get("schema") == RECORD_SCHEMA else None
        except (OSError, ValueError):
            record = None
    return Item("flight", log.stem, log=log, record=record)


def _esc(v: Any) -> str:
    return html.escape(str(v))


def _num(v: Any, fmt: str = "{:.4f}") -> str:
    if isinstance(v, bool) or v is None or isinstance(v, int):
        return "-" if v is None else _esc(v)
    return fmt.format(v) if isinstance(v, float) else _esc(json.dumps(v, default=str)
                                                        if isinstance(v, (dict, list)) else v)


def _table(rows: list[tuple[str, Any]]) -> str:
    return "<table>" + "".join(f"<tr><th>{_esc(k)}</th><td>{v}</td></tr>" for k, v in rows) + \
        "</table>"


def flight_section(item: Item) -> str:
    """The flight's metrics, figures, gains, vehicle, command line and events, as HTML."""
    assert item.log is not None
    flight = read(str(item.log))
    m = flight.metrics()
    rec = item.record or {}
    res = rec.get("result") or {}
    parts = [f"<h2>Flight {_esc(item.name)}</h2>",
             f"<p class=dim>log {_esc(item.log)} ({flight.kind}, {m['records']} records, "
             f"{m['corrupt']} corrupt)</p>"]
    rows = [("f_cost (sqrt of the integral of |p_ref - p|^2, the paper's cost)",
             _num(m.get("f_cost"))),
            ("steady RMS error over the second half (m)", _num(m.get("steady_rms"))),
            ("max error (m)", _num(m.get("max_error"), "{:.3f}")),
            ("mission time logged (s)", _num(m.get("mission_time_s"), "{:.2f}")),
            ("pose samples", m["samples"])]
    for key, label in (("reason", "ended"), ("exit_code", "exit code"),
                       ("mission", "mission"), ("controller", "controller"),
                       ("autopilot", "autopilot"), ("loop_rate_hz", "loop rate (Hz)"),
                       ("latency_p50_ms", "latency p50 (ms)"), ("latency_p99_ms",
                                                                "latency p99 (ms)"),
                       ("missed_cycles", "missed cycles"), ("failsafes", "failsafes"),
                       ("gains_source", "gains from")):
        if key in res:
            rows.append((label, _num(res[key], "{:.3f}")))
    parts.append("<h3>Tracking</h3>" + _table(rows))
    with tempfile.TemporaryDirectory() as tmp:
        title = f"{item.log.name}: f_cost {_num(m.get('f_cost'))}"
        for png in plot_flight(flight, tmp, title):
            data = base64.b64encode(Path(png).read_bytes()).decode()
            parts.append(f'<img alt="{_esc(Path(png).stem)}" src="data:image/png;base64,{data}">')
    if res.get("gains"):
        parts.append("<h3>Gains</h3>" + _table([(k, _num(v, "{:.6g}"))
                                                for k, v in res["gains"].items()]))
    if res.get("limits"):
        parts.append("<h3>Limits</h3>" + _table([(k, _num(v, "{:.6g}"))
                                                 for k, v in res["limits"].items()]))
    if rec:
        parts.append("<h3>Command line</h3><pre>" + _esc(shlex.join(
            str(a) for a in rec.get("command") or [])) + "</pre>")
        if rec.get("vehicle_file"):
            parts.append(f"<h3>Vehicle file {_esc(rec['vehicle_file'])}</h3><pre>"
                         f"{_esc(rec.get('vehicle') or '(not readable when the flight ended)')}"
                         "</pre>")
        else:
            parts.append("<h3>Vehicle file</h3><p>none: default gains or flags</p>")
    else:
        parts.append("<p class=warn>No flight record (<code>.json</code>) beside this log: the "
                     "run did not end cleanly, or it predates records. Gains, vehicle file and "
                     "command line are unknown.</p>")
    if flight.events:
        parts.append("<h3>Events</h3><table><tr><th>vehicle time (s)</th><th>event</th></tr>"
                     + "".join(f"<tr><td>{_num(t, '{:.3f}')}</td><td>{_esc(text)}</td></tr>"
                               for t, text in flight.events) + "</table>")
    return "\n".join(parts)


def page(item: Item) -> str:
    """A whole self-contained HTML page for a flight or a calibration."""
    when = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    if item.kind == "flight":
        body = flight_section(item)
    else:
        body = "\n".join([f"<h2>Calibration {_esc(item.name)}</h2>"] + [
            f"<h3>{_esc(name)}</h3><pre>{_esc(text)}</pre>" for name, text in item.files.items()
        ] + [flight_section(f) for f in item.flights])
    return (f"<!doctype html><html><head><meta charset=utf-8><title>pzc-rover: "
            f"{_esc(item.name)}</title><style>{STYLE}</style></head><body>"
            f"<h1>pzc-rover {item.kind} report: {_esc(item.name)}</h1>"
            f"<p class=dim>made {when} by companion report</p>{body}</body></html>\n")


def write(items: list[Item], out: str) -> list[str]:
    """One page per item: ``out`` itself for one, ``<out stem>-<name>.html`` beside it for
    several (and ``out`` an index of them). The paths written."""
    target = Path(out)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        if len(items) == 1:
            target.write_text(page(items[0]), encoding="utf-8")
            return [str(target)]
        written = []
        links = []
        for item in items:
            p = target.with_name(f"{target.stem}-{item.name}.html")
            p.write_text(page(item), encoding="utf-8")
            written.append(str(p))
            links.append(f'<li><a href="{_esc(p.name)}">{_esc(item.kind)} {_esc(item.name)}</a></li>')
        target.write_text(f"<!doctype html><html><head><meta charset=utf-8><title>pzc-rover "
                          f"reports</title><style>{STYLE}</style></head><body><h1>pzc-rover "
                          f"reports</h1><ul>{''.join(links)}</ul></body></html>\n",
                          encoding="utf-8")
        return [str(target), *written]
    except OSError as exc:
        raise UserError(f"--out {out}: cannot write: {exc.strerror}") from None
