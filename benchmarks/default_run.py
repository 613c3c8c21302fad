"""The default a new user gets: ``companion run`` on stock ArduPilot SITL without a vehicle file.

Boots a fresh ``ardurover`` (``rover-skid``; ``--param NAME=VALUE`` for another vehicle) and
flies ``companion run --mission M --arm`` for each mission given, no ``--vehicle`` or
``--gains``: the run recognises a bundled vehicle by its parameters or warns
(docs/flying.md). Prints, per mission, the steady RMS, the preset matched or the warning.

    python benchmarks/default_run.py missions/example_rover.plan missions/paper_ellipse_004.toml

Needs ``ARDUPILOT_SITL`` (or ``ARDUPILOT_DIR``); prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from testbed.process import ROOT


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("missions", nargs="+")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    args = p.parse_args()
    from testbed.ardupilot import ArduPilotSITL
    params = {k: float(v) for k, v in (item.split("=", 1) for item in args.param)}
    with tempfile.TemporaryDirectory(prefix="default-run-") as tmp:
        sitl = ArduPilotSITL(Path(tmp), params=params).start()
        try:
            for mission in args.missions:
                r = subprocess.run([sys.executable, "-m", "companion", "run", "--connect",
                                    sitl.url(0), "--mission", mission, "--arm", "--json",
                                    "--no-zenoh", "--no-log", "-q", "--telemetry-timeout", "90",
                                    "--arm-timeout", "120", "--origin-timeout", "120"],
                                   capture_output=True, text=True, cwd=ROOT)
                lines = [ln for ln in r.stdout.splitlines() if ln.startswith("{")]
                if not lines:
                    print(f"{mission}: exit {r.returncode}: {r.stderr.strip()[-300:]}")
                    continue
                d = json.loads(lines[-1])
                print(f"{mission}: steady RMS {d['steady_rms']:.3f} m, exit {d['exit_code']} "
                      f"({d['reason']}); " + (f"preset {d['vehicle_preset']}"
                                              if d.get("vehicle_preset") else
                                              d.get("vehicle_warning", "")), flush=True)
        finally:
            sitl.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
