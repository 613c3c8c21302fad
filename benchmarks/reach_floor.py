"""The floor: how close ANY path with a speed limit can stay to the paper's ellipse.

A vehicle that cannot exceed ``V`` m/s cannot follow p_ref = [6 cos - sin, 2 cos + 3 sin](2 pi f_r t)
where the reference is faster; the best it can do is the periodic path p(t) with |p'| <= V that
minimises the RMS of |p - p_ref| over a lap. That is a convex problem (a quadratic cost, one
second-order cone per time step), solved here by ADMM with the circulant difference operator
inverted by FFT. Every acceleration and turn-rate limit is ignored, so the figure is a lower
bound on the steady RMS any controller can reach.

    python benchmarks/reach_floor.py --f-r 0.12 --max-speed 3.03      # -> about 1.17 m
"""

from __future__ import annotations

import argparse
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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--f-r", type=float, default=0.12)
    ap.add_argument("--max-speed", type=float, default=3.03)
    args = ap.parse_args()
    rms, peak = floor(args.f_r, args.max_speed)
    print(f"ellipse at {args.f_r:g} Hz, speed <= {args.max_speed:g} m/s: steady RMS >= {rms:.3f} m "
          f"(solution's peak speed {peak:.3f} m/s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
