"""Helpers for the safety tests: signing keys, a MAVLink frame encoder (optionally signed with
any key), a proxy that can inject frames, process RSS, and reading flight logs back strictly."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from testbed.udp_proxy import Proxy

HOLD, GUIDED = 4, 15


def make_key(path: Path, mode: int = 0o600, data: bytes | None = None) -> Path:
    path.write_bytes(os.urandom(32) if data is None else data)
    path.chmod(mode)
    return path


def encoder(key: bytes | None = None, sysid: int = 255, compid: int = 190,
            link_id: int = 7) -> Any:
    """A pymavlink MAVLink object whose ``*_encode(...)`` messages ``pack`` into frames;
    signed with ``key`` when given (set up as mavfile.setup_signing does)."""
    mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.sign_outgoing = True
        mav.signing.link_id = link_id
        mav.signing.timestamp = int((time.time() - 1420070400) * 100_000)
    return mav


def frame(mav: Any, msg: Any) -> bytes:
    return bytes(msg.pack(mav))


class InjectingProxy(Proxy):
    """The recording proxy of :mod:`testbed.udp_proxy`, plus frames injected from the plant's side
    (same source address as the plant: what a corrupted or hostile link delivers)."""

    def to_companion(self, data: bytes) -> None:
        self.sock.sendto(data, self.companion_addr)

    def to_plant(self, data: bytes) -> None:
        if self.plant_addr is not None:
            self.sock.sendto(data, self.plant_addr)


def rss_kb(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def read_tlog(path: Path) -> tuple[list[tuple[float, Any]], int]:
    """(timestamp, message) of every frame pymavlink parses from a .tlog, and how many did not."""
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    out, bad = [], 0
    try:
        while (msg := conn.recv_msg()) is not None:
            if msg.get_type() == "BAD_DATA":
                bad += 1
            else:
                out.append((msg._timestamp, msg))
    finally:
        conn.close()
    return out, bad
