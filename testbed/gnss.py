"""A field's GNSS for ArduPilot SITL (issue 44): seeded receiver errors to feed ``GPS_INPUT``.

SITL's own GPS has no horizontal noise (``SIM_GPS1_HNSE`` is a slow circle): with
``GPS1_TYPE 14`` ArduPilot takes its fixes from ``GPS_INPUT`` instead
(``../shared/notes/gnss-and-fields.md``), and this module says what such a receiver reports at
each fix: the error it adds to the truth (north, east, m), its fix type and the accuracy it
claims. Pure and seeded: the same scenario and seed give the same fixes, so a benchmark's
scenarios compare the companion with ArduPilot's own following on the very same errors.

The pieces are what users report (the notes' "What real receivers do"):

* white noise, independent at each fix;
* Gauss-Markov drift: the first-order process x[k+1] = a x[k] + sqrt(1 - a^2) sigma w[k],
  a = exp(-dt / tau), whose stationary standard deviation is sigma and correlation time tau
  (RTK's slow centimetre wander, float's decimetres, plain GPS's half metre);
* windows: RTK float (fix type 5, its own drift and claimed accuracy) and multipath jumps (a
  constant offset while the receiver still reports "fixed").

:data:`SCENARIOS` holds the issue's sizes; :func:`fixes` turns one into arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

FIX_3D, FIX_RTK_FLOAT, FIX_RTK_FIXED = 3, 5, 6       # GPS_FIX_TYPE (common.xml)


@dataclass(frozen=True)
class Drift:
    """Gauss-Markov drift: stationary standard deviation ``sigma`` (m, per axis), correlation
    time ``tau`` (s)."""

    sigma: float
    tau: float


@dataclass(frozen=True)
class Window:
    """From ``start`` s for ``duration`` s: RTK float (``drift``, fix type 5, ``h_acc``
    claimed) or, with ``jump`` (north, east, m), a multipath offset while still "fixed"."""

    start: float
    duration: float
    drift: Drift | None = None
    h_acc: float | None = None
    jump: tuple[float, float] | None = None

    def holds(self, t: np.ndarray) -> np.ndarray:
        return (t >= self.start) & (t < self.start + self.duration)


@dataclass(frozen=True)
class Scenario:
    """A receiver: fix rate (Hz) and lag (s, what ``GPS1_DELAY_MS`` should say), its fix type
    and claimed horizontal accuracy (m) in good times, white noise (m, per axis), drift, and
    the windows that spoil it."""

    name: str
    rate_hz: float = 10.0
    lag: float = 0.12
    fix_type: int = FIX_RTK_FIXED
    h_acc: float = 0.014
    white: float = 0.0
    drift: Drift | None = None
    windows: tuple[Window, ...] = ()


SCENARIOS = {s.name: s for s in (
    Scenario("none", h_acc=0.01),
    Scenario("rtk-fixed", white=0.008, drift=Drift(0.01, 30.0)),
    Scenario("rtk-float", white=0.008, drift=Drift(0.01, 30.0),
             windows=(Window(20.0, 15.0, drift=Drift(0.4, 8.0), h_acc=0.4),)),
    Scenario("multipath", white=0.008, drift=Drift(0.01, 30.0),
             windows=tuple(Window(t, 4.0, jump=(0.25 * math.cos(a), 0.25 * math.sin(a)))
                           for t, a in ((15.0, 0.3), (30.0, 2.2), (45.0, 4.1)))),
    Scenario("plain-gps", rate_hz=5.0, lag=0.2, fix_type=FIX_3D, h_acc=0.7, white=0.1,
             drift=Drift(0.5, 60.0)),
)}


@dataclass(frozen=True)
class Fixes:
    """What the receiver says at times ``t`` (s from the scenario's start): its error added to
    the truth (``north``, ``east``, m), ``fix_type`` and the accuracy it claims (``h_acc``)."""

    t: np.ndarray
    north: np.ndarray
    east: np.ndarray
    fix_type: np.ndarray
    h_acc: np.ndarray


def gauss_markov(n: int, dt: float, drift: Drift, rng: np.random.Generator,
                 from_zero: bool = False) -> np.ndarray:
    """``n`` samples, ``dt`` s apart, of one axis of ``drift``: started from its stationary
    distribution (no warm-up transient), or with ``from_zero`` from 0 (it then grows to
    ``sigma`` over about ``tau``)."""
    a = math.exp(-dt / drift.tau)
    w = rng.standard_normal(n) * drift.sigma
    out = np.empty(n)
    x = 0.0 if from_zero else w[0]
    scale = math.sqrt(1.0 - a * a)
    for k in range(n):
        if k:
            x = a * x + scale * w[k]
        out[k] = x
    return out


def fixes(scenario: Scenario, duration: float, seed: int) -> Fixes:
    """The scenario's fixes for ``duration`` s at its rate, from ``seed``."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / scenario.rate_hz
    n = int(math.floor(duration * scenario.rate_hz)) + 1
    t = np.arange(n) * dt
    north, east = np.zeros(n), np.zeros(n)
    if scenario.white > 0:
        north += rng.standard_normal(n) * scenario.white
        east += rng.standard_normal(n) * scenario.white
    if scenario.drift is not None:
        north += gauss_markov(n, dt, scenario.drift, rng)
        east += gauss_markov(n, dt, scenario.drift, rng)
    fix_type = np.full(n, scenario.fix_type, dtype=int)
    h_acc = np.full(n, scenario.h_acc)
    for w in scenario.windows:
        inside = w.holds(t)
        if w.jump is not None:
            north[inside] += w.jump[0]
            east[inside] += w.jump[1]
        if w.drift is not None:
            # float's own wander, from where the fixed solution was (it grows over tau)
            m = int(inside.sum())
            north[inside] += gauss_markov(m, dt, w.drift, rng, from_zero=True)
            east[inside] += gauss_markov(m, dt, w.drift, rng, from_zero=True)
            fix_type[inside] = FIX_RTK_FLOAT
        if w.h_acc is not None:
            h_acc[inside] = w.h_acc
    return Fixes(t, north, east, fix_type, h_acc)
