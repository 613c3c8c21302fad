"""Zenoh at the edge: key names (keys), payloads (codec), session config (config, tls), the session registry (session), a companion's publishers (vehicle), its control queryable (control) and the operator's side (control_client).

May import: ``live`` (events, the control channel), ``security``, ``errors``, ``secretfile``, and zenoh (lazily: a run without Zenoh never loads it).
"""
