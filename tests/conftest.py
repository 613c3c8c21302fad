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

import pytest

# MAVLink 2 frames: set before any test module imports pymavlink (import sorting may put
# `from pymavlink import mavutil` above a harness that sets it; mavutil reads it once)
os.environ["MAVLINK20"] = "1"

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


def pytest_collection_modifyitems(config, items):
    """The long tests (marked slow) first, the rest in their order: on xdist workers (make
    test) the longest then start at once instead of finishing alone at the end. The order
    is the same in every worker, as xdist requires (a stable sort of one collection)."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture
def ardupilot(tmp_path):
    """Start ArduPilot Rover SITL: ``ardupilot(speedup=5, params={"NAME": value})`` returns a
    running ``testbed.ardupilot.ArduPilotSITL``; every one is stopped after the test. Skips when
    neither ARDUPILOT_SITL nor ARDUPILOT_DIR is set."""
    from testbed.ardupilot import sitl_factory
    with sitl_factory(tmp_path) as start:
        yield start


@pytest.fixture
def px4(tmp_path):
    """Start PX4 SITL (SIH Ackermann rover): ``px4(params={"NAME": value})`` returns a running
    ``testbed.px4.PX4SITL``; every one is stopped after the test. Skips when neither PX4_SITL
    nor PX4_DIR is set."""
    from testbed.px4 import px4_factory
    with px4_factory(tmp_path) as start:
        yield start
