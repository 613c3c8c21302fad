"""The vehicle and simulation: the rover model, batch closed loops, Section 5, tuning, gains files.

May import: ``core``, ``errors``; never the MAVLink or Zenoh edges.
"""
