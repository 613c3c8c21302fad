"""How long planning a field takes (issue 45: a 1 ha field at 1 m spacing in at most 1 s).

Plans square fields (a 3 m headland, 1 m spacing, the fewest-turns angle) with
:func:`companion.mission.field.plan`, and loads the same as a mission file (planning plus the
loader's checks: the motion profile, the limits), best of ``--repeat``; prints figures, asserts
nothing.

    python -m benchmarks.bench_field [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from companion import mission as missions
from companion.mission.field import plan
from companion.mission.route import RouteLimits


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=5)
    args = p.parse_args()
    print(f"field planning, best of {args.repeat}; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    print(f"{'field':>10s} {'swaths':>6s} {'route m':>8s} {'plan s':>7s} {'load s':>7s}")
    for side in (100.0, 316.0):
        boundary = [(0.0, 0.0), (side, 0.0), (side, side), (0.0, side)]
        fp = plan(boundary, spacing=1.0, headland=3.0, limits=RouteLimits(speed=2.0))
        planning = best(lambda b=boundary: plan(b, spacing=1.0, headland=3.0,
                                                limits=RouteLimits(speed=2.0)), args.repeat)
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "f.toml"
            path.write_text('frame = "local"\n[trajectory]\nkind = "field"\n'
                            f"boundary = {[list(q) for q in boundary]}\nspacing = 1.0\n"
                            "headland = 3.0\nspeed = 2.0\n")
            loading = best(lambda q=path: missions.load(q), args.repeat)
        print(f"{side * side / 1e4:8.1f} ha {len(fp.swaths):6d} {fp.route.length:8.0f} "
              f"{planning:7.3f} {loading:7.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
