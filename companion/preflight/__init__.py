"""Preflight: what the autopilot must be set to for the companion, as pure checks over what it said (checks), and the reading of it over MAVLink (gather).
May import: ``live`` (the link, the parameter client), ``profiles`` (what to check per autopilot and steering kind), ``errors``; the checks themselves no I/O.
"""
