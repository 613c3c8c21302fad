"""The mission stored on the vehicle, read over MAVLink into a QGroundControl ``.plan``.

Connects like a run (:class:`companion.live.link.Link`: the same identity, signing and serial
handling), waits for the vehicle's heartbeat, reads its mission with the mission protocol
(:mod:`companion.mav.mission_transfer`) and returns it as a .plan, the format
:mod:`companion.mission.plan_import` reads (``companion mission pull``, ``companion run
--mission vehicle``). A vehicle that never answers is a user's problem (exit 2: wrong link or
id); a transfer that started and broke is a fault (exit 3); a partial mission is never returned.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ExitCode, UserError
from ..mav import mission_transfer as mt
from .config import LinkConfig


@dataclass(frozen=True)
class Pulled:
    plan: dict[str, Any]               # the .plan (JSON object)
    items: list[Any]                   # MISSION_ITEM_INT, as stored (home first on ArduPilot)
    profile: Any                       # the vehicle's autopilot profile

    @property
    def count(self) -> int:
        return len(self.items)

    @property
    def homeless(self) -> bool:
        """The vehicle keeps its home in the mission (ArduPilot's item 0) and has none yet: 0, 0
        until its first GPS fix. Such a home is no start point."""
        home = self.plan["mission"].get("plannedHomePosition") or [0, 0]
        return bool(self.profile.mission_home_item) and home[0] == 0 and home[1] == 0


def pull_plan(config: LinkConfig, transfer: mt.TransferConfig = mt.DEFAULT,
              log: Callable[[str], None] = lambda text: None) -> Pulled:
    """The vehicle's mission: as a .plan, as items, and whose it is."""
    from .link import Link
    link = Link(config)
    try:
        v = link.wait_vehicle()
        try:
            items = mt.pull(link.master, v.sysid, v.compid, transfer, log)
        except mt.TransferError as err:
            raise UserError(f"{config.url}: {err}", ExitCode.FAULT if err.started
                            else ExitCode.USER_ERROR) from None
        plan = mt.to_plan(items, v.profile.mission_home_item, vehicle_type=v.mav_type)
        return Pulled(plan, [items.wp(i) for i in range(items.count())], v.profile)
    finally:
        link.close()


def write_plan(plan: dict[str, Any], path: str | Path) -> Path:
    """Write a .plan whole or not at all (a temporary file renamed into place)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    try:
        tmp.write_text(json.dumps(plan, indent=2) + "\n", encoding="utf-8")
        tmp.replace(path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise UserError(f"{path}: cannot write: {exc.strerror or exc}") from None
    return path
