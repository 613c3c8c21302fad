"""``companion log export LOG --mcap OUT.mcap``: a flight log in the robotics tools' format.

LOG is the companion's ``.csv`` or any MAVLink ``.tlog``; OUT.mcap holds the same flight in
Foxglove's standard schemas (``foxglove.PoseInFrame``, ``PosesInFrame``, ``LocationFix``,
``Log``) and JSON-schema channels (the loop's every field; a .tlog's every MAVLink message on
``/mavlink/<TYPE>``), which Foxglove opens without set-up. Topics: companion/live/mcaplog.py.
"""

from __future__ import annotations

import argparse
import json


def register(subparsers) -> None:
    p = subparsers.add_parser("log", help="flight-log tools: export to MCAP (Foxglove)",
                              description=__doc__.split("\n\n", 1)[1],
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="log_command", metavar="ACTION", required=True)
    e = sub.add_parser("export", help="write a .csv or .tlog flight log as MCAP",
                       description=__doc__.split("\n\n", 1)[1],
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    e.add_argument("log", metavar="LOG", help="flight log: .csv or .tlog")
    e.add_argument("--mcap", metavar="OUT.mcap", required=True, help="the MCAP file to write")
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.set_defaults(func=run_export)


def run_export(args) -> int:
    from ..errors import UserError
    from ..logs.export import export

    if not args.mcap.lower().endswith(".mcap"):
        raise UserError(f"--mcap {args.mcap}: the file name must end in .mcap")
    done = export(args.log, args.mcap)
    result = {"log": done.source, "kind": done.kind, "mcap": done.out, "topics": done.written,
              "source": done.source_counts, "skipped": done.skipped}
    if args.json:
        print(json.dumps(result))
        return 0
    total = sum(done.written.values())
    print(f"{done.out}: {total} messages on {len(done.written)} topics from {done.source} "
          f"({done.kind}, {done.skipped} corrupt records skipped)")
    for topic in sorted(done.written):
        print(f"  {topic:<40} {done.written[topic]}")
    return 0
