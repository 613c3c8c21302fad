"""The MAVLink parameter protocol, client side: read every parameter, read some, set one.

* ``fetch_all``: PARAM_REQUEST_LIST, then PARAM_REQUEST_READ by index for every index that did
  not arrive (a radio drops some of a burst of a thousand PARAM_VALUEs), a few rounds;
* ``read``: PARAM_REQUEST_READ by name, asked again each second;
* ``set``: PARAM_SET with the parameter's own type, the vehicle's PARAM_VALUE echo is its read
  back (asked for again with PARAM_REQUEST_READ when the echo is lost).

Values travel as a float32 either way. ArduPilot puts integers in it as their value ("C cast");
PX4 puts their bytes in it ("bytewise", MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE), so an
INT32 of 5 arrives as the float whose bits are 5 (7e-45): the autopilot's profile says which
(``bytewise_params``). :func:`decode` / :func:`encode` turn either into the number a person means.

Other messages read while waiting are handed to ``observe`` (the caller may want the STATUSTEXTs
and SYS_STATUS that arrive meanwhile) and otherwise dropped: only for set-up, never inside the
control loop.
"""

from __future__ import annotations

import math
import struct
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from .link import Link, mavlink

INT_TYPES = {mavlink.MAV_PARAM_TYPE_UINT8: "<B", mavlink.MAV_PARAM_TYPE_INT8: "<b",
             mavlink.MAV_PARAM_TYPE_UINT16: "<H", mavlink.MAV_PARAM_TYPE_INT16: "<h",
             mavlink.MAV_PARAM_TYPE_UINT32: "<I", mavlink.MAV_PARAM_TYPE_INT32: "<i"}
REAL32 = mavlink.MAV_PARAM_TYPE_REAL32


@dataclass(frozen=True)
class Param:
    name: str
    value: float        # what a person means (decoded)
    type: int           # MAV_PARAM_TYPE
    index: int = -1


def decode(raw: float, param_type: int, bytewise: bool) -> float:
    """The parameter's value from PARAM_VALUE.param_value."""
    if bytewise and param_type in INT_TYPES:
        word = struct.pack("<f", raw)
        size = struct.calcsize(INT_TYPES[param_type])
        return float(struct.unpack(INT_TYPES[param_type], word[:size])[0])
    return float(raw)


def encode(value: float, param_type: int, bytewise: bool) -> float:
    """PARAM_SET.param_value for ``value`` of ``param_type``."""
    if bytewise and param_type in INT_TYPES:
        fmt = INT_TYPES[param_type]
        word = struct.pack(fmt, int(round(value))).ljust(4, b"\x00")
        return struct.unpack("<f", word)[0]
    return float(value)


def _name(msg: Any) -> str:
    raw = msg.param_id
    text = raw if isinstance(raw, str) else raw.decode("ascii", "replace")
    return text.split("\x00", 1)[0]


class ParamClient:
    def __init__(self, link: Link, observe: Callable[[Any], None] = lambda msg: None):
        self.link = link
        self.observe = observe
        self.bytewise = link.vehicle.profile.bytewise_params
        self.count: int | None = None          # the vehicle's param_count, once known
        self.retried: int = 0                  # indices asked for again after the list

    # --- receiving ---------------------------------------------------------------------------
    def _pump(self, left: float) -> Param | None:
        """One PARAM_VALUE from the vehicle (None if none came within a short wait)."""
        link = self.link
        msg = link.recv()
        if msg is None:
            link.wait(min(left, 0.05))
            return None
        if msg.get_type() != "PARAM_VALUE" or not link.is_vehicle(msg):
            if msg.get_type() != "BAD_DATA":
                self.observe(msg)
            return None
        if 0 < msg.param_count < 0xFFFF:
            self.count = int(msg.param_count)
        return Param(_name(msg), decode(msg.param_value, msg.param_type, self.bytewise),
                     int(msg.param_type), int(msg.param_index))

    def _request_index(self, index: int) -> None:
        v = self.link.vehicle
        self.link.mav.param_request_read_send(v.sysid, v.compid, b"", index)

    def _request_name(self, name: str) -> None:
        v = self.link.vehicle
        self.link.mav.param_request_read_send(v.sysid, v.compid, name.encode("ascii"), -1)

    # --- the three operations ----------------------------------------------------------------
    def fetch_all(self, timeout: float = 30.0, quiet: float = 1.0, rounds: int = 3
                  ) -> dict[str, Param]:
        """Every parameter: ``{name: Param}``. The list is over when nothing new arrived for
        ``quiet`` seconds; then missing indices are asked for by index, ``rounds`` times.
        Returns what arrived by ``timeout`` (possibly incomplete; compare with :attr:`count`)."""
        v = self.link.vehicle
        found: dict[str, Param] = {}
        by_index: set[int] = set()
        deadline = time.monotonic() + timeout
        self.link.mav.param_request_list_send(v.sysid, v.compid)
        last_new = time.monotonic()
        round_no = 0
        while (left := deadline - time.monotonic()) > 0:
            p = self._pump(left)
            now = time.monotonic()
            if p is not None:
                if p.name not in found or p.index not in by_index:
                    last_new = now
                found[p.name] = p
                if 0 <= p.index < 0xFFFF:      # PX4's _HASH_CHECK comes as index 65535, extra
                    by_index.add(p.index)
                continue
            if self.count is not None and by_index.issuperset(range(self.count)):
                break
            if now - last_new < quiet:
                continue
            if self.count is None:             # nothing at all, or no count: ask again
                if round_no >= rounds:
                    break
                self.link.mav.param_request_list_send(v.sysid, v.compid)
            else:
                missing = [i for i in range(self.count) if i not in by_index]
                if round_no >= rounds or not missing:
                    break
                for i in missing:
                    self._request_index(i)
                self.retried += len(missing)
            round_no += 1
            last_new = now
        return found

    def read(self, names: Iterable[str], timeout: float = 3.0) -> dict[str, Param]:
        """The named parameters that answered within ``timeout`` (asked again each second)."""
        wanted = set(names)
        found: dict[str, Param] = {}
        deadline = time.monotonic() + timeout
        next_ask = 0.0
        while wanted - set(found) and (left := deadline - time.monotonic()) > 0:
            if time.monotonic() >= next_ask:
                for name in sorted(wanted - set(found)):
                    self._request_name(name)
                next_ask = time.monotonic() + 1.0
            p = self._pump(left)
            if p is not None and p.name in wanted:
                found[p.name] = p
        return found

    def set(self, name: str, value: float, param_type: int = REAL32, timeout: float = 3.0,
            tries: int = 3) -> Param | None:
        """PARAM_SET, then the vehicle's value of ``name`` as it answers (None: no answer).
        The answer is what the vehicle now holds, which may not be ``value`` (a firmware may
        clamp it or refuse it)."""
        if not math.isfinite(value):
            raise ValueError(f"{name}: not a finite value: {value!r}")
        v = self.link.vehicle
        raw = encode(value, param_type, self.bytewise)
        per_try = timeout / tries
        for _ in range(tries):             # setting twice is harmless; the echo may be lost
            self.link.mav.param_set_send(v.sysid, v.compid, name.encode("ascii"), raw,
                                         param_type)
            deadline = time.monotonic() + per_try
            while (left := deadline - time.monotonic()) > 0:
                p = self._pump(left)
                if p is not None and p.name == name:
                    return p
        return None


def read_values(link: Link, names: Iterable[str], timeout: float = 2.0) -> dict[str, float]:
    """The vehicle's values of the parameters ``names`` (PARAM_REQUEST_READ by name, asked
    again each second): ``{name: value}`` for those answered within ``timeout`` seconds; a
    parameter the firmware does not have is simply missing. Other messages read meanwhile are
    dropped: only for set-up, before the control loop."""
    return {name: p.value for name, p in ParamClient(link).read(list(names), timeout).items()}
