"""The parameters the plant serves (PARAM_REQUEST_LIST / PARAM_REQUEST_READ / PARAM_SET).

The autopilot profile's list (``PlantFacts.params``, :mod:`companion.profiles`): ArduPilot
Rover's names (or PX4's) for what the plant models, so ``companion preflight`` and
``companion identify`` read a plant as they read a vehicle:

* the inner-loop limits from the plant's own :class:`~companion.sim.plant.RoverParams`
  (ATC_ACCEL_MAX, ATC_DECEL_MAX, ATC_STR_RAT_MAX, ATC_STR_ACC_MAX, ATC_STR_DEC_MAX in ArduPilot's
  units, 0 for no limit; CRUISE_SPEED at CRUISE_THROTTLE 50 % and WP_SPEED from the top speed);
* the frame: a skid-steer rover (FRAME_CLASS 1, SERVO1_FUNCTION 73, SERVO3_FUNCTION 74); PX4:
  CA_AIRFRAME 6;
* the failsafe settings at the firmware's defaults (FS_GCS_ENABLE 0, FS_ACTION 2,
  FS_GCS_TIMEOUT 5, MAV_GCS_SYSID 255; PX4: COM_OF_LOSS_T the plant's offboard timeout,
  COM_OBL_RC_ACT 5 as the plant switches to Hold), SCHED_LOOP_RATE the plant's loop rate.

The plant only stores what is set: the failsafes, the frame and the limits are not acted on
(the limits were read when the plant started), except FRAME_CLASS 2, which makes the heartbeat
a boat's as ArduPilot's does. ``--param NAME=VALUE`` overrides any of them at start (or adds
one, served as a float). Values travel as ArduPilot sends them (integers as their value) or, where
the profile says so (PX4), bytewise (an INT32's bytes in the float).
"""

from __future__ import annotations

import math
import random
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

UINT8, INT8, UINT16, INT16, UINT32, INT32, REAL32 = 1, 2, 3, 4, 5, 6, 9
_INT_FORMATS = {UINT8: "<B", INT8: "<b", UINT16: "<H", INT16: "<h", UINT32: "<I", INT32: "<i"}
FRAME_CLASS_BOAT = 2
MAV_TYPE_GROUND_ROVER, MAV_TYPE_SURFACE_BOAT = 10, 11


@dataclass
class Entry:
    value: float
    type: int


class ParamTable:
    """The served parameters; PARAM_SET changes them for the process's lifetime."""

    def __init__(self, entries: list[tuple[str, float, int]], bytewise: bool = False,
                 overrides: tuple[tuple[str, float], ...] = (), loss: float = 0.0,
                 seed: int = 0):
        self.entries: dict[str, Entry] = {n: Entry(float(v), t) for n, v, t in entries}
        for name, value in overrides:
            if name in self.entries:
                self.entries[name].value = float(value)
            else:
                self.entries[name] = Entry(float(value), REAL32)
        self.names = list(self.entries)
        self.bytewise = bytewise
        self.loss = loss                          # share of a list reply lost (a radio's)
        self._rng = random.Random(seed)
        self.sets = 0

    def get(self, name: str) -> float | None:
        e = self.entries.get(name)
        return None if e is None else e.value

    def _raw(self, e: Entry) -> float:
        if self.bytewise and e.type in _INT_FORMATS:
            word = struct.pack(_INT_FORMATS[e.type], int(e.value)).ljust(4, b"\x00")
            return struct.unpack("<f", word)[0]
        return e.value

    def _decode(self, raw: float, e: Entry) -> float | None:
        if self.bytewise and e.type in _INT_FORMATS:
            size = struct.calcsize(_INT_FORMATS[e.type])
            return float(struct.unpack(_INT_FORMATS[e.type], struct.pack("<f", raw)[:size])[0])
        if not math.isfinite(raw):
            return None
        return float(int(raw)) if e.type in _INT_FORMATS else float(raw)

    def handle(self, msg: Any, send: Callable[[str, float, int, int, int], None]) -> bool:
        """Answer one PARAM_* message with PARAM_VALUEs through ``send(name, raw value, type,
        count, index)``; True when a parameter changed."""
        kind, count = msg.get_type(), len(self.names)
        if kind == "PARAM_REQUEST_LIST":
            for i, name in enumerate(self.names):
                if self.loss and self._rng.random() < self.loss:
                    continue
                e = self.entries[name]
                send(name, self._raw(e), e.type, count, i)
            return False
        name = _name(msg.param_id)
        if kind == "PARAM_REQUEST_READ":
            index = int(msg.param_index)
            if index >= 0:
                if index >= count:
                    return False
                name = self.names[index]
            if name not in self.entries:
                return False                  # as ArduPilot: an unknown name gets no answer
            e = self.entries[name]
            send(name, self._raw(e), e.type, count, self.names.index(name))
            return False
        if kind == "PARAM_SET" and name in self.entries:
            e = self.entries[name]
            value = self._decode(msg.param_value, e)
            changed = value is not None and value != e.value
            if value is not None:
                e.value = value
                self.sets += 1
            send(name, self._raw(e), e.type, count, self.names.index(name))
            return changed
        return False

    def mav_type(self) -> int:
        """The heartbeat's MAV_TYPE as ArduPilot Rover derives it from FRAME_CLASS."""
        return MAV_TYPE_SURFACE_BOAT if self.get("FRAME_CLASS") == FRAME_CLASS_BOAT \
            else MAV_TYPE_GROUND_ROVER


def _name(raw: Any) -> str:
    text = raw if isinstance(raw, str) else bytes(raw).decode("ascii", "replace")
    return text.split("\x00", 1)[0]


def parse_override(text: str) -> tuple[str, float]:
    """``NAME=VALUE`` for ``--param``; ValueError with a one-line reason."""
    name, sep, value = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise ValueError(f"{text!r}: expected NAME=VALUE")
    if len(name) > 16 or not all(c.isalnum() or c == "_" for c in name):
        raise ValueError(f"{text!r}: a parameter name is up to 16 letters, digits or _")
    try:
        number = float(value)
    except ValueError:
        raise ValueError(f"{text!r}: {value!r} is not a number") from None
    if not math.isfinite(number):
        raise ValueError(f"{text!r}: the value must be finite")
    return name.upper(), number
