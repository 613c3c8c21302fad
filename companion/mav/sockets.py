"""Socket set-up both ends of a MAVLink link share: a receive buffer big enough for bursts.

The kernel's default UDP receive buffer holds about 256 small datagrams; a burst beyond it (a
ground station's parameter download, a plant catching up after a stall) is dropped silently.
"""

from __future__ import annotations

import socket
from typing import Any

RECV_BUFFER = 4 << 20   # bytes asked for (Linux caps it at net.core.rmem_max, then doubles it)


def size_receive_buffer(conn: Any, size: int = RECV_BUFFER) -> int | None:
    """Ask for a ``size``-byte receive buffer on a UDP connection; the size granted, or None."""
    sock = getattr(conn, "port", None)
    if not isinstance(sock, socket.socket) or sock.type != socket.SOCK_DGRAM:
        return None
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)
        return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    except OSError:
        return None
