"""pzc-rover companion: the model-free filter and PZC tracking law of Lee et al. (2024) for
skid-steer and Ackermann rovers on ArduPilot and PX4, and the MAVLink process that runs them on
a companion computer.

Conventions (used by every module):

* Frame: the paper's plane frame (x, y, phi) *is* MAVLink's local NED frame seen from above:
  x = north, y = east, phi = yaw measured from north towards east. Both are right-handed about
  the down axis, so eq. (1) ``x' = v cos(phi)``, ``y' = v sin(phi)`` holds with no sign flips.
* Units: metres, seconds, radians. Angles are wrapped to (-pi, pi] (:func:`companion.core.angles.wrap`).
* The mathematics (``core``: ``filter``, ``pzc``, ``baselines``, ``trajectory``; and
  ``sim.plant``) is pure: no I/O, no clock, no globals. Every state variable may be a Python float (one vehicle, the live loop) or
  a numpy array (many vehicles, batch simulation); the same objects serve both.

Layers (each subpackage's docstring says what it may import; imports run one way, downwards):

* ``core``: the paper's mathematics, pure;
* ``sim``: the vehicle model, batch simulation, Section 5, tuning, gains files;
* ``mission``: mission files and trajectory kinds;
* ``mav``: MAVLink plumbing shared with ``sitl_plant`` (signing keys, sockets);
* ``live``: the live loop at the MAVLink edge, and the flight logs it writes;
* ``bus``: the Zenoh edge (a sink of the loop's events, and its control channel);
* ``logs``: flight logs read back and plotted;
* ``commands``: one module per CLI command, wired by ``cli``; ``errors``, ``progress`` and
  ``secretfile`` are helpers any layer may use.
"""

__version__ = "0.1.0"
