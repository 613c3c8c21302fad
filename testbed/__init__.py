"""The test bed the tests and the benchmarks share: SITL launchers, the companion as a process, fakes, missions, scoring.
May import: companion, sitl_plant (and pymavlink, zenoh); companion and sitl_plant never import it.

Modules: :mod:`~testbed.sitl` (what both SITL launchers share), :mod:`~testbed.ardupilot` and
:mod:`~testbed.px4` (the autopilots as processes, their ground stations), :mod:`~testbed.process`
(``python -m companion`` as a process), :mod:`~testbed.missions` (mission files, the stand-still
mission that waits for a SITL's boot), :mod:`~testbed.scoring` (the simulator's truth, a flight
log's figures, f_cost and the steady RMS), :mod:`~testbed.baselines` (the autopilot's own
following, Kanayama's hand-picked gains), :mod:`~testbed.reach_floor` (the best any path can do);
and the tests' fakes: :mod:`~testbed.fake_vehicle`, :mod:`~testbed.udp_proxy`,
:mod:`~testbed.field_faults`, :mod:`~testbed.mission_gcs`, :mod:`~testbed.origin`,
:mod:`~testbed.safety`, :mod:`~testbed.fuzz`, :mod:`~testbed.pty_cable`,
:mod:`~testbed.zenoh_fleet` (those on a link of their own share :mod:`~testbed.link_thread`);
a field's GNSS for SITL: :mod:`~testbed.gnss` (seeded receiver errors) and
:mod:`~testbed.gnss_input` (fed to ArduPilot as GPS_INPUT); :mod:`~testbed.marks` (the suite's
pytest marks: the only module that imports pytest).

Installed with the project (pyproject.toml), so ``python -m benchmarks.NAME``, ``python
benchmarks/NAME.py`` and pytest all import it without touching ``sys.path``; it runs from the
checkout (:data:`testbed.process.ROOT`: ``missions/``, ``benchmarks/``).
"""

import os

# MAVLink 2 frames on every link the test bed opens: set before any of its modules imports
# pymavlink (mavutil reads it once, at import; a package's __init__ runs before its modules).
os.environ["MAVLINK20"] = "1"
