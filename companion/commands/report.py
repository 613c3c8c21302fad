"""``companion report LOGDIR [--out report.html]``: one self-contained HTML page per flight or
calibration in LOGDIR (or for one log file): the paper's metrics, the figures inline, the gains
and limits, the vehicle file and the command line (from the record each flight writes beside
its log), the events. Opens offline; several flights give one page each and an index.
"""

from __future__ import annotations

import argparse
import json


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "report", help="a self-contained HTML report per flight or calibration",
        description=__doc__.split("\n\n", 1)[0].split(": ", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("logdir", metavar="LOGDIR", help="a folder of flight logs (or one log), or "
                   "a calibrate --out folder")
    p.add_argument("--out", metavar="FILE", default="report.html",
                   help="the page to write (default report.html)")
    p.add_argument("--json", action="store_true", help="print the pages written as JSON")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..errors import UserError
    from ..logs.report import find, write
    if not args.out.lower().endswith((".html", ".htm")):
        raise UserError(f"--out {args.out}: the file name must end in .html")
    pages = write(find(args.logdir), args.out)
    if args.json:
        print(json.dumps({"pages": pages}))
    else:
        for path in pages:
            print(f"report      {path}")
    return 0
