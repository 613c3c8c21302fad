"""Mutual TLS and role access control in a session's Zenoh config, from ``--zenoh-tls DIR/NAME``
or from the config file's own certificate: Zenoh does the TLS and the access control; this
writes its settings, after checking what Zenoh would only report as a failed handshake.

A session over mutual TLS listens only where the flags or the file say (Zenoh's default
listener is in clear). Peers reach each other only over links they open to one another (a
router relays nothing between two of its peers: its failover brokering has had no effect since
Zenoh 1.9), so a peer with no listener is heard by no other peer, only by clients. A session
whose mode nobody chose, given somewhere to connect and nowhere to listen, is therefore made a
*client*: everything goes through what it connects to, as ``--zenoh-mode client`` would.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from .config import BusOptions, get, put

if TYPE_CHECKING:       # loads the cryptography library: only sessions with TLS need it
    from ..security.identity import Identity


def secure(config, opts: BusOptions, file: str | None, mode_chosen: bool) -> Identity | None:
    """Write mutual TLS and access control into ``config`` when ``--zenoh-tls`` or the file's
    own TLS certificate asks for it (the checked identity), else leave it (None).

    ``file`` names the config file in messages; ``mode_chosen``: a flag or the file set the mode
    (else a listener-less session connecting somewhere becomes a client, see the module)."""
    import zenoh

    from ..security import tls
    own = get(config, tls.TLS_KEY) or {}
    cert = own.get("connect_certificate") or own.get("listen_certificate")
    key = own.get("connect_private_key") or own.get("listen_private_key")
    if opts.tls is None and not (own.get("root_ca_certificate") and cert and key):
        return None
    from ..security import acl
    from ..security import identity as ids
    if opts.tls is not None:
        me = ids.from_spec(opts.tls, opts.roles)
    else:
        assert cert is not None and key is not None   # all three given: see the return above
        me = ids.load(Path(own["root_ca_certificate"]), Path(cert), Path(key), opts.roles,
                      where=f"{file} (transport/link/tls)", key_flag=f"{file}: key")
    # Zenoh's default listener (a peer's tcp/[::]:0, a router's tcp/[::]:7447) is in clear:
    # listen only where the flags or the file say.
    if not opts.listen and get(config, "listen/endpoints") == get(zenoh.Config(),
                                                                  "listen/endpoints"):
        put(config, "listen/endpoints", [], "mutual TLS")
    mode = get(config, "mode") or "peer"
    if not mode_chosen and mode == "peer" and _listens_nowhere_connects_somewhere(config):
        mode = "client"
        put(config, "mode", mode, "mutual TLS")
    for setting, given, flag in (("listen/endpoints", opts.listen, "--zenoh-listen"),
                                 ("connect/endpoints", opts.connect, "--zenoh-connect")):
        where = flag if given else f"{file or 'Zenoh default'}: {setting}"
        tls.check_endpoints(tls.endpoints_for(get(config, setting), mode), where)
    put(config, tls.TLS_KEY, tls.settings(me), "mutual TLS")
    # A file that writes its own access control keeps it (its author chose); else the roles'.
    if not (get(config, "access_control") or {}).get("enabled"):
        put(config, "access_control", acl.access_control(me.role, me.name, me.roster),
            "access control")
    return me


def _listens_nowhere_connects_somewhere(config) -> bool:
    """Plain lists (endpoints per mode are a file's own choice, kept): none to listen on, some
    to connect to."""
    listen, connect = get(config, "listen/endpoints"), get(config, "connect/endpoints")
    return isinstance(listen, list) and isinstance(connect, list) and not listen and bool(connect)
