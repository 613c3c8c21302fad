"""One inner-loop channel over a whole command series, many models at once: identification's loop.

:func:`lag_series` runs :func:`companion.sim.actuator.lag_step` (the exact rate-limited lag of
``_channel``, then the overshoot of ``overshoot_step``) for ``n`` parameter sets over every grid
step of a delayed, clamped command, the loop :mod:`companion.ident.channels` spends a fit in.

Stepped by numpy, a step costs about 25 array operations whatever ``n`` is (about 40 us: a
two-log fit made 628,560 such calls, 26 of its 45 s); compiled by numba (when it is installed:
x86-64 and 64-bit ARM wheels on PyPI) the same arithmetic runs per model as plain floats. Both
paths compute the same numbers (to rounding: ``tests/sim/test_lag_series.py``); ``compiled=False``
forces the numpy one, which is the reference.

Pure: arrays in, arrays out (numba's cache of the compiled loop aside, next to this file or in
the user's cache directory).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ..core import ops
from ..core.signals import Num
from .actuator import lag_step

_compiled: Callable[..., None] | None = None     # the loop below, compiled (when numba is here)


def _params(n: int, *values: Num) -> list[np.ndarray]:
    """Each per-model parameter as a contiguous float64 array of length ``n``."""
    return [np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)))
            for v in values]


def lag_series(padded: np.ndarray, offset: np.ndarray, top: np.ndarray, steps: int, x0: float,
               bandwidth: Num, accel: Num, decel: Num, dt: float, overshoot: Num,
               overshoot_s: Num, compiled: bool = True, capped: bool = False) -> np.ndarray:
    """The channel's output on ``steps`` grid steps for ``n = len(offset)`` models: shape
    (steps, n), row k the output at the start of step k (row 0 is ``x0``).

    Model i's command at step k is ``padded[k + offset[i]]`` (a pure delay: the series padded
    with zeros in front, each model reading it ``offset[i]`` places later), clamped to
    ``+-top[k, i]`` (``top`` of shape (steps or 1, n or 1): a clamp that moves with the other
    channel, or a fixed one). ``bandwidth`` (rad/s), ``accel`` / ``decel`` (rate limits while
    |x| grows / shrinks), ``overshoot`` and ``overshoot_s`` (g and tau of ``overshoot_step``):
    numbers or arrays of length n. Every output at the start of each step, as respond records.
    ``capped`` (the turn rate's channel): an overshooting output (g != 0) is capped at
    ``+-top[k, i]`` as well (:func:`companion.sim.actuator.turn_rate_cap`); x and z run on."""
    offset = np.ascontiguousarray(offset, dtype=np.int64)
    n = len(offset)
    top = np.ascontiguousarray(np.asarray(top, dtype=np.float64).reshape(
        np.shape(top)[0] if np.ndim(top) == 2 else 1, -1))
    b, up, down, g, tau = _params(n, bandwidth, accel, decel, overshoot, overshoot_s)
    over = bool(np.any(g != 0))
    padded = np.ascontiguousarray(padded, dtype=np.float64)
    if compiled and _compiled is not None:
        out = np.empty((steps, n))
        _compiled(padded, offset, top, float(x0), b, up, down, g, tau, float(dt), over, capped,
                  out)
        return out
    return _stepped(padded, offset, top, steps, float(x0), b, up, down, g, tau, float(dt), over,
                    capped)


def _stepped(padded: np.ndarray, offset: np.ndarray, top: np.ndarray, steps: int, x0: float,
             b: np.ndarray, up: np.ndarray, down: np.ndarray, g: np.ndarray, tau: np.ndarray,
             dt: float, over: bool, capped: bool) -> np.ndarray:
    """The reference: :func:`lag_step` on arrays of all ``n`` models, one grid step a call."""
    n = len(offset)
    m = ops.for_size(n)
    by_step = top.shape[0] > 1
    x = np.full(n, x0)
    y, z = x, x
    out = np.empty((steps, n))
    for k in range(steps):
        out[k] = y
        limit = top[k] if by_step else top[0]
        u = m.clip(padded[k + offset], -limit, limit)
        y, x, z = lag_step(m, x, z, u, b, up, down, dt, g, tau, over, limit if capped else None)
    return out


def _loop(padded: Any, offset: Any, top: Any, x0: float, b: Any, up: Any, down: Any, g: Any,
          tau: Any, dt: float, over: bool, capped: bool, out: Any) -> None:   # pragma: no cover
    """:func:`_stepped` per model on floats: ``_channel``'s exact step (x(h) only) and
    ``overshoot_step``, the same operations in the same order (compiled by numba; as Python,
    the reference for the compiled loop's tests)."""
    steps, n = out.shape
    rows, cols = top.shape
    x = np.full(n, x0)                            # the lag's output
    z = np.full(n, x0)                            # the overshoot's slow state
    y = np.full(n, x0)                            # what is measured
    keep = np.exp(-dt / tau)                      # overshoot_step's 1 - k
    decay = np.exp(-b * dt)                       # a whole step of the unclipped lag
    for k in range(steps):                        # step-major: rows of out, top in order
        row = k if rows > 1 else 0
        for i in range(n):
            out[k, i] = y[i]
            limit = top[row, i if cols > 1 else 0]
            u = min(max(padded[k + offset[i]], -limit), limit)
            e0 = u - x[i]
            rate = down[i] if e0 * x[i] < 0 else up[i]
            knee = rate / b[i]
            t1 = max(abs(e0) / rate - 1.0 / b[i], 0.0)
            e1 = min(max(e0, -knee), knee)        # the error when the ramp ends
            tr = min(dt, t1)                      # time spent ramping at the rate limit
            te = dt - tr                          # then decaying
            if t1 <= 0:                           # the usual case: no ramp, no exp
                x1 = u - e1 * decay[i]
            elif te > 0:
                x1 = u - e1 * math.exp(-b[i] * te)
            else:                                 # ramping all step long
                x1 = x[i] + (-rate if e0 < 0 else rate) * tr
            if over:
                z[i] = z[i] + (1.0 - keep[i]) * (0.5 * (x[i] + x1) - z[i])
                y[i] = (1.0 + g[i]) * x1 - g[i] * z[i]
                if capped and g[i] != 0.0:
                    y[i] = min(max(y[i], -limit), limit)
            else:
                y[i] = x1
            x[i] = x1


try:                                     # an optional accelerator: the numpy path is complete
    import numba
except ImportError:                      # pragma: no cover - platforms without numba's wheels
    pass
else:
    try:
        _compiled = numba.njit(cache=True, nogil=True)(_loop)
    except RuntimeError:                 # pragma: no cover - "no locator available": read-only
        _compiled = numba.njit(nogil=True)(_loop)
