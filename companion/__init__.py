"""pzc-rover companion: the model-free filter and PZC tracking law of Lee et al. (2024)
for differential-drive rovers, and the MAVLink process that runs them on a companion computer.

Conventions (used by every module):

* Frame: the paper's plane frame (x, y, phi) *is* MAVLink's local NED frame seen from above:
  x = north, y = east, phi = yaw measured from north towards east. Both are right-handed about
  the down axis, so eq. (1) ``x' = v cos(phi)``, ``y' = v sin(phi)`` holds with no sign flips.
* Units: metres, seconds, radians. Angles are wrapped to (-pi, pi] (:func:`companion.angles.wrap`).
* The mathematics (``filter``, ``pzc``, ``baselines``, ``plant``, ``trajectory``) is pure: no I/O,
  no clock, no globals. Every state variable may be a Python float (one vehicle, the live loop) or
  a numpy array (many vehicles, batch simulation); the same objects serve both.
"""

__version__ = "0.1.0"
