"""The key expressions a companion uses, and the vehicle id that names them (a contract).

``<vehicle_id>`` defaults to ``rover<sysid>``, e.g. ``rover1``::

    rover/<vehicle_id>/state     put, one per control cycle (or every N-th: --state-every N)
    rover/<vehicle_id>/status    put, one per life-cycle event
    rover/<vehicle_id>/control   queryable, only with --control-secret FILE

The payloads are in :mod:`companion.bus.codec`, the control requests in
:mod:`companion.bus.control`.
"""

from __future__ import annotations

import re

from ..errors import UserError

_VEHICLE_ID = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")   # one key-expression chunk, no wildcards


def state_key(vehicle_id: str) -> str:
    return f"rover/{vehicle_id}/state"


def status_key(vehicle_id: str) -> str:
    return f"rover/{vehicle_id}/status"


def control_key(vehicle_id: str) -> str:
    return f"rover/{vehicle_id}/control"


def check_vehicle_id(text: str) -> str:
    if not _VEHICLE_ID.match(text):
        raise UserError(f"--vehicle-id {text!r}: use 1-64 letters, digits, '_', '-' or '.' "
                        "(it becomes one chunk of the key rover/<vehicle_id>/...)")
    return text
