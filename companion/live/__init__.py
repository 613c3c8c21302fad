"""The live loop at the MAVLink edge: link, telemetry checks, runner, session, stats, events, flight logs written.

May import: ``core``, ``sim.gains``, ``mission``, ``mav``, ``profiles``, ``errors``; never ``bus`` (Zenoh is a sink it is handed).
"""
