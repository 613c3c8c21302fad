"""Flying under a field's GNSS and scoring it from the simulator's truth (issue 44), for the
SITL tests and ``benchmarks/gnss_truth.py``.

:func:`gnss_vehicle` readies an ArduPilot SITL that takes its fixes from the injector
(:mod:`testbed.gnss_input`: ``GPS1_TYPE 14``, ``GPS_INPUT`` on SERIAL2, the truth from
``SIM_STATE``); :func:`companion_trace` reads a companion run's tracked cycles (its CSV, timed by
its .tlog); :func:`score` gives the figures the benchmark prints:

* ``truth``: steady RMS over the last ``STEADY_S`` s of the true position against the
  reference that flight flew;
* ``estimate``: the same against LOCAL_POSITION_NED (what every figure before issue 44 used);
* ``floor``: the estimate's RMS error against the truth over the same seconds, both taken
  relative to where they were when tracking began (the anchoring of the reference);
* per window of the scenario: ``worst`` (the largest truth error against the reference point
  over the tracked cycles in it; a held reference leaves the braking distance in it),
  ``from_path`` (the largest distance from the path itself, shapely's, of every truth sample in
  the window: a rover held has no tracked cycles but a true place) and ``after`` (the largest truth error over half a
  second, ``AFTER_S`` after the window).

The truth is SIM_STATE on the injector's link, matched to a flight's samples on the vehicle's
clock (:class:`Truth`), by wall time where a flight's samples do not carry it.
"""

from __future__ import annotations

import bisect
import csv
import math
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from shapely import LineString, Point

from .gnss import Scenario
from .gnss_input import GnssInjector
from .missions import wait_ready
from .safety import read_tlog

STEADY_S = 30.0
AFTER_S = 5.0


@contextmanager
def gnss_vehicle(sitl: Any, scenario: Scenario, seed: int, logs: Path,
                 ready_timeout: float = 400.0) -> Iterator[GnssInjector]:
    """A started ArduPilot SITL (``sitl``, with :func:`testbed.gnss_input.sitl_params` among its
    parameters) fed by the injector, stood still until its estimate is ready: the injector,
    for a ``with`` block (its :meth:`~testbed.gnss_input.GnssInjector.begin` times the
    scenario's windows)."""
    ready: dict = {}
    url = sitl.url(0)
    waiter = threading.Thread(target=lambda: ready.update(s=wait_ready(url, logs)), daemon=True)
    waiter.start()                    # SITL opens SERIAL2 once SERIAL0 has a client
    sitl.wait_log("SERIAL2 on TCP port", 60)
    with GnssInjector(sitl.url(2), scenario, seed) as inj:
        waiter.join(ready_timeout)
        if "s" not in ready:
            raise AssertionError(f"{scenario.name}: the vehicle never became ready")
        yield inj


class Truth:
    """The injector's truth (wall s, north, east), interpolated at a wall time, or (given the
    injector's ``clock``) at a vehicle time.

    On the vehicle's clock is the sharper of the two: a flight's samples carry the vehicle time
    of the estimate they answer (LOCAL_POSITION_NED's ``time_boot_ms``), and the truth gets its
    vehicle time from the same message arriving beside it on the injector's link; by wall time,
    each link's own delivery (the streams' send slots, the reader's wake-up) lands in the
    match, centimetres at a metre a second."""

    def __init__(self, samples: list[tuple[float, float, float]],
                 clock: list[tuple[float, float]] | None = None):
        self.walls = [w for w, _, _ in samples]
        self.samples = samples
        self.vehicle: np.ndarray | None = None
        if clock and len(clock) >= 2:
            walls, times = np.array(clock).T
            vehicle = np.interp(self.walls, walls, times, left=np.nan, right=np.nan)
            seen = np.isfinite(vehicle)           # the truth within the clock's span
            self.vehicle = vehicle[seen]
            self._north = np.array([n for _, n, _ in samples])[seen]
            self._east = np.array([e for _, _, e in samples])[seen]

    def at_vehicle(self, t: float) -> tuple[float, float] | None:
        """The truth at vehicle time ``t`` (s; None outside what was seen or without a clock)."""
        v = self.vehicle
        if v is None or not len(v) or not (v[0] <= t <= v[-1]):
            return None
        return float(np.interp(t, v, self._north)), float(np.interp(t, v, self._east))

    def at(self, wall: float) -> tuple[float, float] | None:
        i = bisect.bisect_right(self.walls, wall)
        if i == 0 or i == len(self.walls):
            return None
        (w0, n0, e0), (w1, n1, e1) = self.samples[i - 1], self.samples[i]
        a = (wall - w0) / (w1 - w0) if w1 > w0 else 0.0
        return n0 + a * (n1 - n0), e0 + a * (e1 - e0)


def companion_trace(result: dict) -> list[tuple[float, ...]]:
    """(wall, mission s, reference x, y, estimate x, y, vehicle s) of each tracked cycle of a
    companion run: its CSV's rows, timed by the arrival of their LOCAL_POSITION_NED in its
    .tlog and by that sample's own vehicle time."""
    frames, _ = read_tlog(Path(result["tlog"]))
    arrival = {}
    for wall, m in frames:
        if m.get_type() == "LOCAL_POSITION_NED" and m.get_srcComponent() == 1:
            arrival.setdefault(m.time_boot_ms, wall)
    out = []
    with open(result["csv"], newline="") as f:
        for row in csv.DictReader(f):
            if not row["mission_time"] or not row["x_ref"]:
                continue
            wall = arrival.get(round(float(row["vehicle_time"]) * 1000))
            if wall is not None:
                out.append((wall, float(row["mission_time"]), float(row["x_ref"]),
                            float(row["y_ref"]), float(row["x"]), float(row["y"]),
                            float(row["vehicle_time"])))
    return out


def score(trace, truth: Truth, scenario: Scenario, duration: float, t0_wall: float,
          steady_s: float = STEADY_S) -> dict:
    """The figures of one flight (module docstring). ``t0_wall``: when the scenario's fixes
    began (its windows are timed from there). ``trace``'s rows: (wall, mission s, reference
    x, y, estimate x, y[, vehicle s]); with their vehicle times and the truth's clock the truth
    is matched on the vehicle's clock (``matched``), else by wall time."""
    on_clock = truth.vehicle is not None and all(len(r) > 6 for r in trace)
    rows = [(r, truth.at_vehicle(r[6]) if on_clock else truth.at(r[0])) for r in trace]
    rows = [(r, p) for r, p in rows if p is not None]
    if not rows:
        return {"error": "no truth matched the flight's samples"}
    (_, _, _, _, ex0, ey0, *_), (tn0, te0) = rows[0]
    path = LineString([(r[2], r[3]) for r, _ in rows])    # where the reference went
    truth_err, est_err, floor, by_wall, by_mt = [], [], [], [], []
    for (wall, mt, xr, yr, xe, ye, *_), (tn, te) in rows:
        xt, yt = tn - tn0 + ex0, te - te0 + ey0          # the truth in the estimate's frame
        e_truth = math.hypot(xr - xt, yr - yt)
        by_wall.append((wall - t0_wall, e_truth))
        by_mt.append((e_truth, mt))
        if mt >= duration - steady_s:
            truth_err.append(e_truth)
            est_err.append(math.hypot(xr - xe, yr - ye))
            floor.append(math.hypot(xe - xt, ye - yt))

    def rms(v: list[float]) -> float:
        return math.sqrt(sum(x * x for x in v) / len(v)) if v else math.nan
    faults = []
    for w in scenario.windows:
        end = w.start + w.duration                       # s from t0_wall
        inside = [e for t, e in by_wall if w.start <= t < end]
        # from the path: every truth sample in the window, the rover held or not (a held rover
        # has no tracked cycles, but it has a true place)
        away = [path.distance(Point(n - tn0 + ex0, e - te0 + ey0))
                for wall, n, e in truth.samples if w.start <= wall - t0_wall < end]
        after = [e for t, e in by_wall if end + AFTER_S <= t < end + AFTER_S + 0.5]
        faults.append({"start": w.start, "worst": max(inside, default=math.nan),
                       "from_path": max(away, default=math.nan),
                       "after": max(after, default=math.nan)})
    return {"truth": rms(truth_err), "estimate": rms(est_err), "floor": rms(floor),
            "worst": max(by_mt), "faults": faults, "samples": len(rows),
            "matched": "vehicle time" if on_clock else "wall time"}


def truth_between(inj: GnssInjector, t0: float, t1: float) -> list[tuple[float, float]]:
    """The injector's true (north, east) between wall times ``t0`` and ``t1`` (time.time())."""
    return [(n, e) for w, n, e in list(inj.truth) if t0 <= w <= t1]
