"""The floor: how close ANY path with a speed limit can stay to the paper's ellipse.

A vehicle that cannot exceed ``V`` m/s cannot follow p_ref = [6 cos - sin, 2 cos + 3 sin](2 pi f_r t)
where the reference is faster; the best it can do is the periodic path p(t) with |p'| <= V that
minimises the RMS of |p - p_ref| over a lap. That is a convex problem (a quadratic cost, one
second-order cone per time step), solved here by ADMM with the circulant difference operator
inverted by FFT. Every acceleration and turn-rate limit is ignored, so the figure is a lower
bound on the steady RMS any controller can reach.

An acceleration limit (``--max-accel`` / ``--max-decel``, ArduPilot's ATC_ACCEL_MAX /
ATC_DECEL_MAX: on the speed, the rate at which it may grow and shrink) makes the problem
non-convex over all paths; :func:`path_floor` takes the reference's own path and finds the best
progress along it, s(t) with 0 <= s' <= V and -decel <= s'' <= accel (convex again: the same
ADMM on the arc length's periodic deviation e = s - s_ref, the boxes clipped per step), scored
as |p(s) - p(s_ref)|. Riding the reference's path is one way to go, so this is what a vehicle
with those limits can do *on the path*, not a bound over every path; at 0.08 Hz the ellipse
asks 0.80 m/s^2 of tangential acceleration (0.20 at 0.04 Hz): with ATC_ACCEL_MAX 0.5 (decel 2)
the floor along the path is 0.060 m (2026-12-02; 4000 iterations of the unscaled solver,
as first committed, stopped short of the boxes and said 0.013 m).

``benchmarks/reach_floor.py`` prints either; ``benchmarks/vehicle_matrix.py`` sets each row beside them.
"""

from __future__ import annotations

import math

import numpy as np


def floor(f_r: float, max_speed: float, n: int = 800, rho: float = 200.0,
          iterations: int = 30000) -> tuple[float, float]:
    """(lower bound on the steady RMS in m, the solution's peak speed in m/s)."""
    period = 1.0 / f_r
    dt = period / n
    wt = 2.0 * math.pi * f_r * np.arange(n) * dt
    ref = np.stack([6 * np.cos(wt) - np.sin(wt), 2 * np.cos(wt) + 3 * np.sin(wt)], axis=1)
    step = max_speed * dt                          # |p[k+1] - p[k]| <= step
    eig = 2.0 - 2.0 * np.cos(2.0 * math.pi * np.arange(n) / n)   # of D^T D, D circulant
    p = ref.copy()
    z = np.roll(p, -1, axis=0) - p
    u = np.zeros_like(z)
    for _ in range(iterations):
        v = z - u
        rhs = ref + rho * (np.roll(v, 1, axis=0) - v)              # ref + rho D^T v
        p = np.real(np.fft.ifft(np.fft.fft(rhs, axis=0) / (1.0 + rho * eig)[:, None], axis=0))
        dp = np.roll(p, -1, axis=0) - p
        q = dp + u
        length = np.linalg.norm(q, axis=1, keepdims=True)
        z = q * np.minimum(1.0, step / np.maximum(length, 1e-12))  # project onto the balls
        u = u + dp - z
    error = np.linalg.norm(p - ref, axis=1)
    speed = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1) / dt
    return float(np.sqrt(np.mean(error ** 2))), float(speed.max())


def _ellipse(wt: np.ndarray) -> np.ndarray:
    return np.stack([6 * np.cos(wt) - np.sin(wt), 2 * np.cos(wt) + 3 * np.sin(wt)], axis=1)


def path_floor(f_r: float, max_speed: float, max_accel: float, max_decel: float,
               n: int = 500, rho: float = 1e-3, iterations: int = 6000) -> tuple[float, float]:
    """(steady RMS in m of the best progress along the reference's path, the largest along-path
    lag in m) for a vehicle with that top speed and acceleration / deceleration (module
    docstring). The boxes are on e's first and second differences in m/s and m/s^2 (scaled by
    the step, so one ``rho`` suits every f_r); what the solution asks is checked against them."""
    period = 1.0 / f_r
    dt = period / n
    fine = 20 * n                               # the path's arc length, finely
    wt = 2.0 * math.pi * np.arange(fine + 1) / fine
    pts = _ellipse(wt)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    lap = float(arc[-1])
    s_ref = arc[::20][:n]                       # at the n sample times
    fwd = lambda e: (np.roll(e, -1) - e) / dt                          # noqa: E731
    sec = lambda e: (np.roll(e, -1) - 2 * e + np.roll(e, 1)) / dt ** 2  # noqa: E731
    v_ref = np.diff(np.append(s_ref, lap)) / dt                 # s_ref' (periodic)
    a_ref = (v_ref - np.roll(v_ref, 1)) / dt                    # s_ref'' at k
    lo1, hi1 = -v_ref, max_speed - v_ref
    lo2, hi2 = -max_decel - a_ref, max_accel - a_ref
    eig1 = (2.0 - 2.0 * np.cos(2.0 * math.pi * np.arange(n) / n)) / dt ** 2
    eig = 1.0 + rho * (eig1 + (eig1 * eig1))
    e = np.zeros(n)
    z1, z2 = np.clip(fwd(e), lo1, hi1), np.clip(sec(e), lo2, hi2)
    u1, u2 = np.zeros(n), np.zeros(n)
    for _ in range(iterations):
        v1, v2 = z1 - u1, z2 - u2
        rhs = rho * ((np.roll(v1, 1) - v1) / dt + sec(v2))     # A1^T v1 + A2^T v2
        e = np.real(np.fft.ifft(np.fft.fft(rhs) / eig))
        a1, a2 = fwd(e), sec(e)
        z1, z2 = np.clip(a1 + u1, lo1, hi1), np.clip(a2 + u2, lo2, hi2)
        u1, u2 = u1 + a1 - z1, u2 + a2 - z2
    here = np.interp(np.mod(s_ref + e, lap), arc, np.arange(fine + 1)) * 2.0 * math.pi / fine
    error = np.linalg.norm(_ellipse(here) - _ellipse(2.0 * math.pi * np.arange(n) / n), axis=1)
    return float(np.sqrt(np.mean(error ** 2))), float(np.max(np.abs(e)))
