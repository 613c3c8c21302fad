"""The live fleet view: what the bus says of each rover (fleet.py), drawn with Rerun (draw.py).
May import: bus, errors.
"""
