"""Missions: the mission file (TOML, QGroundControl .plan, .waypoints), trajectory kinds, geodesy, plots.

May import: ``core``, ``sim`` (rover parameters, gains files), ``errors``; no MAVLink or Zenoh.
"""

from .file import Mission, from_local_points, load, loads, paper_ellipse

__all__ = ["Mission", "from_local_points", "load", "loads", "paper_ellipse"]
