"""The plant's stored mission and its side of the MAVLink mission protocol.

What ArduPilot's ``GCS_MAVLINK`` mission handling does, cut to what a ground station and the
companion use (mavlink.io "Mission Protocol"): an upload (MISSION_COUNT, then MISSION_REQUEST_INT
for each item, MISSION_ITEM_INT answers, MISSION_ACK at the end), a download (MISSION_REQUEST_LIST
-> MISSION_COUNT, MISSION_REQUEST_INT / MISSION_REQUEST -> MISSION_ITEM_INT), MISSION_CLEAR_ALL,
MISSION_SET_CURRENT and MISSION_CURRENT. Items are kept exactly as received (integers in 1e-7
degrees), so a download gives back what was uploaded. The plant's uploads are answered one
request per item; an uploader that goes quiet simply leaves the old mission in place.

Item 0 is the vehicle's home, as on ArduPilot: what was uploaded there until the vehicle has a
home (its first GPS fix: the plant's origin set, ``home_e7``), the home itself from then on.

``drop_item`` (``--mission-drop-item N``): a fault for the tests, the plant never answers a
request for item N (a link that loses it every time), so a download cannot complete.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

MISSION_TYPE = 0
ACCEPTED, ERROR, NO_SPACE, INVALID_SEQUENCE = 0, 1, 4, 13
MAX_ITEMS = 700            # ArduPilot's storage on a small board holds a few hundred


@dataclass
class MissionStore:
    drop_item: int | None = None
    items: list[Any] = field(default_factory=list)       # MISSION_ITEM_INT messages
    current: int = 0
    _upload: list[Any] | None = None                     # items of an upload under way
    _upload_count: int = 0
    uploads: int = 0
    home_e7: tuple[int, int] | None = None               # the vehicle's home, once it has one

    def handle(self, msg: Any, mav: Any, send: Callable[[Callable[..., None]], Callable[..., None]]
               ) -> bool:
        """Answer one mission-protocol message on ``mav`` (its link's pymavlink MAVLink);
        ``send`` wraps a send function so a link error is dropped. True if it was one."""
        kind = msg.get_type()
        if getattr(msg, "mission_type", MISSION_TYPE) != MISSION_TYPE:
            if kind in ("MISSION_REQUEST_LIST", "MISSION_COUNT"):
                send(mav.mission_ack_send)(msg.get_srcSystem(), msg.get_srcComponent(),
                                           1, msg.mission_type)   # MAV_MISSION_UNSUPPORTED
            return kind.startswith("MISSION_")
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if kind == "MISSION_REQUEST_LIST":
            send(mav.mission_count_send)(*src, len(self.items), MISSION_TYPE)
        elif kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            seq = int(msg.seq)
            if seq == self.drop_item:
                return True
            if not 0 <= seq < len(self.items):
                send(mav.mission_ack_send)(*src, INVALID_SEQUENCE, MISSION_TYPE)
                return True
            it = self.items[seq]
            x, y = self.home_e7 if seq == 0 and self.home_e7 is not None else (it.x, it.y)
            send(mav.mission_item_int_send)(*src, seq, it.frame, it.command,
                                            int(seq == self.current), it.autocontinue,
                                            it.param1, it.param2, it.param3, it.param4,
                                            x, y, it.z, MISSION_TYPE)
        elif kind == "MISSION_COUNT":
            count = int(msg.count)
            if count > MAX_ITEMS:
                send(mav.mission_ack_send)(*src, NO_SPACE, MISSION_TYPE)
                return True
            if count == 0:
                self.items, self.current = [], 0
                send(mav.mission_ack_send)(*src, ACCEPTED, MISSION_TYPE)
                return True
            self._upload, self._upload_count = [], count
            send(mav.mission_request_int_send)(*src, 0, MISSION_TYPE)
        elif kind == "MISSION_ITEM_INT" and self._upload is not None:
            if int(msg.seq) != len(self._upload):
                # a repeat of an item already taken, or one out of order: ask for the next
                send(mav.mission_request_int_send)(*src, len(self._upload), MISSION_TYPE)
                return True
            self._upload.append(msg)
            if len(self._upload) < self._upload_count:
                send(mav.mission_request_int_send)(*src, len(self._upload), MISSION_TYPE)
            else:
                self.items, self._upload = self._upload, None
                self.current = 1 if len(self.items) > 1 else 0
                self.uploads += 1
                send(mav.mission_ack_send)(*src, ACCEPTED, MISSION_TYPE)
        elif kind == "MISSION_CLEAR_ALL":
            self.items, self.current, self._upload = [], 0, None
            send(mav.mission_ack_send)(*src, ACCEPTED, MISSION_TYPE)
        elif kind == "MISSION_SET_CURRENT":
            if 0 <= int(msg.seq) < len(self.items):
                self.current = int(msg.seq)
            send(mav.mission_current_send)(self.current)
        else:
            return kind.startswith("MISSION_")
        return True
