"""The fleet drawn with Rerun: its SDK serves the gRPC stream and its web viewer from this
machine (``rr.serve_grpc``, ``rr.serve_web_viewer``; the viewer's wasm and JavaScript ship inside
the ``rerun-sdk`` wheel, so no internet is needed), and :class:`Drawing` logs what
:class:`~companion.view.fleet.Fleet` knows.

Entities (one set per vehicle id ``<id>``):

* ``map/<id>/reference_path``, ``map/<id>/driven``: line strips, the reference seen so far
  (grey) and the path driven (the rover's colour);
* ``map/<id>/rover``: the rover, labelled with its id and state, coloured by it (green tracking,
  orange paused, red failsafe or pilot override, blue done or stopped, grey **stale**);
  ``map/<id>/target``: the reference point now;
* ``error/<id>``: |p_ref - p|; ``setpoint/<id>/speed``, ``setpoint/<id>/yaw_rate``: what was sent
  (a state sample every ``PLOT_EVERY`` s, on the ``wall`` timeline at the companion's
  ``sent_at``);
* ``events/<id>``: the life-cycle events as a text log; ``fleet``: a table of every rover (state,
  failsafe, mode, armed, error, setpoints, age of the last message), with the paths every
  ``path_every`` s (0.5); the rover and its target every redraw.

The map is in local metres, east to the right and north up: Rerun's 2D views point y down, so a
point is drawn at (east, -north) (the hover shows -north).
"""

from __future__ import annotations

import math
import time
from typing import Any

from .fleet import Snapshot

COLOURS = {"tracking": (40, 200, 90), "resumed": (40, 200, 90), "paused": (255, 165, 0),
           "failsafe": (235, 50, 50), "pilot_override": (235, 50, 50),
           "mission_done": (80, 140, 255), "stopped": (80, 140, 255)}
STALE = (128, 128, 128)
PATHS = [(0, 190, 255), (255, 90, 200), (255, 220, 0), (150, 110, 255), (0, 230, 200)]
REFERENCE = (170, 170, 170)
PLOT_EVERY = 0.1           # s between two plotted points of a series


def _require() -> Any:
    try:
        import rerun as rr
    except ImportError as exc:
        from ..errors import UserError
        raise UserError("companion view needs Rerun's SDK: pip install 'pzc-rover[view]' "
                        f"({exc})") from None
    return rr


def _xy(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    return [(y, -x) for x, y in points]


class Drawing:
    """One Rerun recording, served over gRPC with the web viewer beside it."""

    def __init__(self, grpc_port: int, web_port: int, memory_limit: str = "512MiB"):
        rr = self.rr = _require()
        import rerun.blueprint as rrb
        rr.init("pzc-rover fleet", spawn=False)
        blueprint = rrb.Blueprint(
            rrb.Horizontal(
                rrb.Spatial2DView(origin="/map", name="fleet map (east →, north ↑, m)"),
                rrb.Vertical(
                    rrb.TextDocumentView(origin="/fleet", name="rovers"),
                    rrb.TimeSeriesView(origin="/error", name="|p_ref - p| (m)"),
                    rrb.TimeSeriesView(origin="/setpoint", name="setpoints"),
                    rrb.TextLogView(origin="/events", name="events"),
                    row_shares=[2, 2, 2, 2]),
                column_shares=[3, 2]),
            collapse_panels=True)
        # newest_first: a browser that connects late gets the fleet as it is now first,
        # then the history (not minutes of backlog before the present)
        self.grpc_url = rr.serve_grpc(grpc_port=grpc_port, default_blueprint=blueprint,
                                      server_memory_limit=memory_limit, newest_first=True)
        rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=self.grpc_url)
        from urllib.parse import quote
        self.url = f"http://127.0.0.1:{web_port}/?url={quote(self.grpc_url, safe='')}"
        self._colour: dict[str, tuple[int, int, int]] = {}
        self._drawn_paths: dict[str, tuple[int, int]] = {}
        self._last_paths = 0.0
        self.frames = 0

    def colour(self, vid: str) -> tuple[int, int, int]:
        return self._colour.setdefault(vid, PATHS[len(self._colour) % len(PATHS)])

    def draw(self, rovers: list[Snapshot], path_every: float = 0.5) -> None:
        rr = self.rr
        now = time.time()
        paths_due = now - self._last_paths >= path_every
        for r in rovers:
            last_t = -math.inf
            for t, err, speed, rate in r.series:
                # the plots at most every PLOT_EVERY s: a browser drawing with a software
                # rasteriser falls behind a 50 Hz stream of three series per rover
                if t - last_t < PLOT_EVERY:
                    continue
                last_t = t
                rr.set_time("wall", timestamp=t)
                if math.isfinite(err):
                    rr.log(f"error/{r.vehicle_id}", rr.Scalars(err))
                if math.isfinite(speed):
                    rr.log(f"setpoint/{r.vehicle_id}/speed", rr.Scalars(speed))
                if math.isfinite(rate):
                    rr.log(f"setpoint/{r.vehicle_id}/yaw_rate", rr.Scalars(rate))
            rr.set_time("wall", timestamp=now)
            for ev in r.events:
                level = ("WARN" if ev.get("kind") in ("failsafe", "pilot_override", "gnss")
                         else "INFO")
                rr.log(f"events/{r.vehicle_id}",
                       rr.TextLog(f"{r.vehicle_id}: {ev.get('kind')}: {ev.get('reason', '')}",
                                  level=level))
            self._rover(r, paths_due)
        if paths_due:
            self._last_paths = now
            rr.log("fleet", rr.TextDocument(table(rovers), media_type="text/markdown"))
        self.frames += 1

    def _rover(self, r: Snapshot, paths_due: bool) -> None:
        rr = self.rr
        vid = r.vehicle_id
        sizes = (len(r.driven), len(r.reference))
        if paths_due and sizes != self._drawn_paths.get(vid) and r.driven:
            self._drawn_paths[vid] = sizes
            if len(r.reference) > 1:
                rr.log(f"map/{vid}/reference_path",
                       rr.LineStrips2D([_xy(r.reference)], colors=[REFERENCE], radii=[0.04],
                                       draw_order=1.0))
            if len(r.driven) > 1:
                rr.log(f"map/{vid}/driven",
                       rr.LineStrips2D([_xy(r.driven)], colors=[self.colour(vid)],
                                       radii=[0.06], draw_order=2.0))
        state = r.state or {}
        pose, ref = state.get("pose") or {}, state.get("reference") or {}
        colour = STALE if r.stale else COLOURS.get(r.phase, (255, 255, 255))
        if _finite(pose.get("x"), pose.get("y")):
            rr.log(f"map/{vid}/rover",
                   rr.Points2D([(pose["y"], -pose["x"])], colors=[colour], radii=[0.35],
                               labels=[label(r)], show_labels=True, draw_order=4.0))
        if _finite(ref.get("x"), ref.get("y")):
            rr.log(f"map/{vid}/target",
                   rr.Points2D([(ref["y"], -ref["x"])], colors=[REFERENCE], radii=[0.15],
                               draw_order=3.0))


def _finite(*values: Any) -> bool:
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in values)


def label(r: Snapshot) -> str:
    if r.stale:
        return f"{r.vehicle_id} STALE ({r.age:.0f} s)"
    if r.failsafe:
        return f"{r.vehicle_id} FAILSAFE: {r.failsafe}"
    return f"{r.vehicle_id} {r.phase}"


def table(rovers: list[Snapshot]) -> str:
    """The rovers as a markdown table (what the ``fleet`` panel shows)."""
    rows = ["| rover | state | failsafe | mode | armed | error m | speed sp | yaw-rate sp | age s |",
            "|---|---|---|---|---|---|---|---|---|"]
    for r in rovers:
        s = r.state or {}
        err = (s.get("error") or {}).get("position")
        sp = s.get("setpoint") or {}

        def num(v: Any, fmt: str = "{:.2f}") -> str:
            return fmt.format(v) if isinstance(v, (int, float)) and math.isfinite(v) else "-"
        state = ("**STALE**" if r.stale else r.phase)
        armed = {True: "yes", False: "no"}.get(bool(s["armed"]), "-") if s.get("armed") is not None else "-"
        rows.append(f"| {r.vehicle_id} | {state} | {r.failsafe or '-'} | {s.get('mode') or '-'} "
                    f"| {armed} | {num(err)} | {num(sp.get('speed'))} "
                    f"| {num(sp.get('yaw_rate'))} | {num(r.age, '{:.1f}')} |")
    if not rovers:
        rows.append("| (no rover seen yet) | | | | | | | | |")
    return "\n".join(rows)
