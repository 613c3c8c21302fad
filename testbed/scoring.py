"""Scoring a flight: from the simulator's truth (SIMSTATE in metres), from a companion's flight
csv (its largest error, a held reference, the share of time its yaw-rate setpoint sat at its
limit), and the paper's tracking figures (f_cost, the steady RMS over the last half) from
position errors sampled over a mission; and a live run's batch twin (the same scenario in
:func:`companion.sim.batch.simulate`).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from itertools import pairwise
from typing import Any

EARTH = 6378100.0      # m: ArduPilot's flat-earth radius (AP_Common/Location.cpp)


# --------------------------------------------------------------------------- the truth

def north_east(lat_e7: float, lon_e7: float, lat0_e7: float, lon0_e7: float
               ) -> tuple[float, float]:
    """A position (1e-7 degrees) in metres north / east of another, on ArduPilot's flat earth."""
    dn = (lat_e7 - lat0_e7) * 1e-7 * math.pi / 180 * EARTH
    de = ((lon_e7 - lon0_e7) * 1e-7 * math.pi / 180 * EARTH
          * math.cos(lat0_e7 * 1e-7 * math.pi / 180))
    return dn, de


def simstate_xy(msg: Any, origin: Any) -> tuple[float, float]:
    """SIMSTATE's true position (1e-7 degrees) in metres north / east of ``origin``'s."""
    return north_east(msg.lat, msg.lng, origin.lat, origin.lng)


# --------------------------------------------------------------------------- a companion's csv

def _tracked_rows(csv_path: str) -> list[tuple[float, float, float]]:
    """(vehicle time, mission time, err_pos) of each tracked cycle in a companion's flight csv."""
    with open(csv_path, newline="") as f:
        return [(float(row["vehicle_time"]), float(row["mission_time"]), float(row["err_pos"]))
                for row in csv.DictReader(f) if row["mission_time"]]


def largest_error(csv_path: str, after_s: float) -> float:
    """The companion's largest position error (its flight csv's ``err_pos``) from mission time
    ``after_s`` on."""
    return max((e for _, mt, e in _tracked_rows(csv_path) if mt >= after_s), default=math.nan)


def held_reference(csv_path: str) -> tuple[float, float, float]:
    """Across the longest pause in tracking (between two tracked cycles of the companion's csv):
    (vehicle seconds it lasted, mission seconds the reference moved meanwhile, the position
    error on the first cycle after it). A reference held while the rover stood moves by one
    cycle, or on to where the rover came to rest on the path (``core.pacing.rejoin``: what it
    braked or ran on through counts as driven), so the error after it is small; one that ran on
    moves as far as the vehicle's clock and leaves the rover behind."""
    rows = _tracked_rows(csv_path)
    gaps = [(b[0] - a[0], b[1] - a[1], b[2]) for a, b in zip(rows, rows[1:], strict=False)]
    return max(gaps, default=(0.0, 0.0, math.nan))


def at_limit_share(csv_path: str, limit: float, duration: float = 60.0) -> float:
    """Share of the last half's cycles with the yaw-rate setpoint at its limit (from the CSV)."""
    values = []
    with open(csv_path) as f:
        for row in csv.DictReader(f):
            try:
                t, w = float(row["mission_time"]), float(row["yaw_rate_cmd"])
            except (TypeError, ValueError):
                continue
            if t >= duration / 2:
                values.append(abs(w) >= 0.98 * limit)
    return sum(values) / len(values) if values else math.nan


# --------------------------------------------------------------------------- the paper's figures

def tracking_figures(errors: Sequence[tuple[float, float]], duration: float) -> dict[str, Any]:
    """From (mission time, |p_ref - p|) samples: ``f_cost`` (the paper's cost, the trapezoidal
    integral of the squared error, square-rooted), ``samples`` and ``steady_rms`` (the RMS over
    the mission's second half)."""
    cost = math.sqrt(sum(0.5 * (a ** 2 + b ** 2) * (tb - ta)
                         for (ta, a), (tb, b) in pairwise(errors)))
    steady = [e for t, e in errors if t >= duration / 2]
    return {"f_cost": cost, "samples": len(errors),
            "steady_rms": math.sqrt(sum(e * e for e in steady) / len(steady))}


# --------------------------------------------------------------------------- the batch twin

def batch_twin(result: dict[str, Any], delay: float = 0.0) -> float:
    """The f_cost of companion.sim.batch.simulate on a ``companion run --json`` result's
    scenario (the paper's 0.12 Hz ellipse, 60 s, 40 Hz, the paper's plant with d_cen 0.3): the same gains, limits, rate, plant, start;
    ``delay`` s of link transit on both channels (zero over loopback)."""
    from companion.core.filter import FilterGains
    from companion.core.limits import Limits
    from companion.core.pzc import PZCGains, PZCTracker
    from companion.core.trajectory import Ellipse
    from companion.sim.batch import SimConfig, simulate
    from companion.sim.plant import RoverParams
    g = result["gains"]
    tracker = PZCTracker(FilterGains(g["k_df"], g["lambda_f"]),
                         PZCGains(**{k: g[k] for k in ("k_dc", "lambda_c", "k_dc_yaw",
                                                       "lambda_c_yaw", "velocity_ff",
                                                       "heading_rate_ff", "speed_law")}),
                         Limits(**result["limits"]))
    plant = RoverParams.paper(d_cen=0.3).with_(speed_delay=delay, yaw_delay=delay)
    sim = simulate(tracker, plant, Ellipse.paper(0.12),
                   config=SimConfig(duration=60.0, control_rate=40.0, start=(0.0, 0.0, 0.0)))
    return float(sim.f_cost)
