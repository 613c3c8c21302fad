"""The live loop at the MAVLink edge: link, telemetry checks, runner, session, stats, events, flight logs written.

May import: ``core``, ``sim.gains`` (and ``sim.vehicle_file`` / ``sim.vehicle_gains`` for the bundled vehicles, presets.py), ``mission``, ``mav``, ``profiles``, ``errors``; never ``bus`` (Zenoh is a sink it is handed).
"""
