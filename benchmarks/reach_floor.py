"""The floor: how close ANY path with a speed limit can stay to the paper's ellipse (the solver and
what it means: :mod:`testbed.reach_floor`).

    python benchmarks/reach_floor.py --f-r 0.12 --max-speed 3.03      # -> about 1.17 m

With an acceleration limit, the floor along the reference's own path (:func:`path_floor`):

    python benchmarks/reach_floor.py --f-r 0.08 --max-speed 3.1 --max-accel 0.5 --max-decel 2
"""

from __future__ import annotations

import argparse

from testbed.reach_floor import floor, path_floor


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--f-r", type=float, default=0.12)
    ap.add_argument("--max-speed", type=float, default=3.03)
    ap.add_argument("--max-accel", type=float, help="m/s^2: the floor along the path")
    ap.add_argument("--max-decel", type=float, help="m/s^2 (default: --max-accel)")
    args = ap.parse_args()
    if args.max_accel is not None:
        decel = args.max_decel if args.max_decel is not None else args.max_accel
        rms, lag = path_floor(args.f_r, args.max_speed, args.max_accel, decel)
        print(f"ellipse at {args.f_r:g} Hz, speed <= {args.max_speed:g} m/s, acceleration "
              f"<= {args.max_accel:g} / deceleration <= {decel:g} m/s^2, on the reference's "
              f"path: steady RMS >= {rms:.3f} m (largest lag along it {lag:.3f} m)")
        return 0
    rms, peak = floor(args.f_r, args.max_speed)
    print(f"ellipse at {args.f_r:g} Hz, speed <= {args.max_speed:g} m/s: steady RMS >= {rms:.3f} m "
          f"(solution's peak speed {peak:.3f} m/s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
