"""``companion plot LOG --out DIR``: the paper's figures and tracking metrics from a flight log.

LOG is the companion's ``.csv`` (everything: reference, filtered pose, setpoints) or any MAVLink
``.tlog`` (the companion's, or one a ground station recorded on a real vehicle): pose telemetry
and setpoints; give ``--mission FILE`` to rebuild the reference from the mission.
"""

from __future__ import annotations

import argparse
import json


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "plot", help="figures and tracking metrics from a flight log (.csv or .tlog)",
        description=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("log", metavar="LOG", help="flight log: .csv or .tlog")
    p.add_argument("--out", metavar="DIR", default="out",
                   help="where the PNG files go (default out/)")
    p.add_argument("--mission", metavar="FILE",
                   help="the mission flown (a .tlog has no reference in it)")
    p.add_argument("--origin", metavar="LAT,LON", help="EKF origin, for geodetic missions")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from ..errors import UserError
    from ..logs.logread import read
    from ..logs.plot import plot_flight

    mission = None
    if args.mission:
        from ..app.flight import load_mission
        mission = load_mission(args.mission, args.origin)
    flight = read(args.log, mission)
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"--out {out}: cannot create it: {exc.strerror}") from None
    m = flight.metrics()
    title = f"{Path(flight.source).name}: " + (
        f"f_cost {m['f_cost']:.3f}, steady RMS {m['steady_rms']:.3f} m"
        if m["f_cost"] is not None and m["steady_rms"] is not None else "no reference")
    figures = plot_flight(flight, out, title)
    result = {"log": flight.source, "kind": flight.kind, **m, "figures": figures,
              "events": [text for _, text in flight.events]}
    if args.json:
        print(json.dumps(result))
        return 0

    def num(key, fmt):
        return "n/a" if m.get(key) is None else format(m[key], fmt)
    print(f"log         {flight.source} ({flight.kind}, {m['records']} records, "
          f"{m['corrupt']} corrupt)")
    print(f"samples     {m['samples']} over {m['vehicle_time_s']:.2f} s of vehicle time")
    print(f"tracking    f_cost {num('f_cost', '.4f')}, steady RMS {num('steady_rms', '.4f')} m, "
          f"max error {num('max_error', '.3f')} m over {num('mission_time_s', '.2f')} s of mission")
    for path in figures:
        print(f"figure      {path}")
    return 0
