"""Suite-wide: every Zenoh session the tests open, or the processes they start open, is
isolated: multicast scouting off, listening on loopback port 0 unless told otherwise.

``companion run`` and ``companion demo`` publish over Zenoh by default; ``$ZENOH_CONFIG`` (which
they read when no ``--zenoh-config`` is given) points them at this file, so no test ever joins or
scouts a network.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

ISOLATED_ZENOH = """{
  mode: "peer",
  scouting: { multicast: { enabled: false } },
  listen: { endpoints: ["tcp/127.0.0.1:0"] },
  connect: { endpoints: [] },
}
"""


_PATH = Path(tempfile.gettempdir()) / f"pzc-rover-zenoh-isolated-{os.getpid()}.json5"


def pytest_configure(config):
    _PATH.write_text(ISOLATED_ZENOH)
    os.environ["ZENOH_CONFIG"] = str(_PATH)


def pytest_unconfigure(config):
    _PATH.unlink(missing_ok=True)
