"""The live loop at the MAVLink edge: link, telemetry checks, runner, session, stats, events, flight logs written.

May import: ``core``, ``sim`` (gains and models; never the tuner), ``mission``, ``mav``, ``profiles``, ``vehicle`` (the loaded vehicle record), ``errors``; never ``bus`` (Zenoh is a sink it is handed), and it opens no vehicle file.
"""
