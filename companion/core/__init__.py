"""The paper's mathematics, pure: filter, PZC law, lead, limits, baselines, the ellipse reference.

May import: the standard library and numpy only (no I/O, no clock, no other companion package).
"""
