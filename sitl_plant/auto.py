"""The plant's AUTO: the stored mission flown by the plant itself, with ArduPilot Rover's guided
sub-mode at ``MAV_CMD_NAV_GUIDED_ENABLE``.

What ``Rover/mode_auto.cpp`` does, cut to what ``companion run --handover`` meets: item 0 is
home and skipped; a NAV_WAYPOINT (16) is driven to (the plant's own guidance) and counts as
reached within ``wp_radius`` (WP_RADIUS, 2 m), which sends MISSION_ITEM_REACHED and starts the
next item; DO_CHANGE_SPEED (178) sets the speed (param2); NAV_GUIDED_ENABLE (92) with param1 > 0
enters the guided sub-mode (``do_nav_guided_enable``): the companion's setpoints are obeyed
(with GUIDED's 3 s timeout) and the item completes only when the vehicle is within
``wp_radius`` of the item's location, if it has one (``verify_nav_guided_enable``), or when
MISSION_SET_CURRENT moves the mission on; param1 0 completes at once. Other items are passed
over. After the last item the rover stops, still in AUTO ("Mission Complete"). Not modelled:
``DO_GUIDED_LIMITS``, jumps, loiters, delays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from companion.mission import geo
from companion.profiles.setpoint import PositionTarget
from companion.sim.plant import RoverParams, RoverState

from . import guidance
from .mission import MissionStore

NAV_WAYPOINT, NAV_GUIDED_ENABLE, DO_CHANGE_SPEED = 16, 92, 178
SEVERITY_INFO = 6


@dataclass
class Auto:
    store: MissionStore
    origin: tuple[float, float]            # the EKF origin: mission lat / lon -> local metres
    wp_radius: float = 2.0
    speed: float = 2.0                     # WP_SPEED until a DO_CHANGE_SPEED
    seq: int = -1                          # the item being run
    guided: bool = False                   # in the guided sub-mode
    target: tuple[float, float] | None = None   # where the item ends (local), if anywhere
    complete: bool = False
    reached: list[int] = field(default_factory=list)      # MISSION_ITEM_REACHED to send
    texts: list[tuple[int, str]] = field(default_factory=list)

    def can_start(self) -> bool:
        return len(self.store.items) > 1           # ArduPilot: "No Mission. Can't set AUTO."

    def start(self, state: RoverState) -> None:
        """Entering AUTO: run the current item (1 after an upload)."""
        self.complete = False
        self._begin(max(1, self.store.current), state)

    def _local(self, it) -> tuple[float, float]:
        return geo.ne_from_latlon(it.x / 1e7, it.y / 1e7, self.origin)

    def _begin(self, seq: int, state: RoverState) -> None:
        items = self.store.items
        self.guided, self.target = False, None
        while seq < len(items):
            it = items[seq]
            cmd = int(it.command)
            if cmd == NAV_WAYPOINT:
                self.target = self._local(it)
                break
            if cmd == NAV_GUIDED_ENABLE and it.param1 > 0:
                self.guided = True
                if it.x != 0 or it.y != 0:
                    self.target = self._local(it)
                break
            if cmd == DO_CHANGE_SPEED and math.isfinite(it.param2) and it.param2 > 0:
                self.speed = float(it.param2)
            seq += 1                                # DO items and disables complete at once
        self.seq = self.store.current = min(seq, max(0, len(items) - 1))
        if seq >= len(items):
            self.complete, self.guided, self.target = True, False, None
            self.texts.append((SEVERITY_INFO, "Mission Complete"))

    def step(self, state: RoverState) -> None:
        """Each physics step in AUTO: a MISSION_SET_CURRENT from outside, or the item done."""
        if self.store.current != self.seq and 0 < self.store.current < len(self.store.items):
            self._begin(self.store.current, state)     # moved on by MISSION_SET_CURRENT
            return
        if self.complete or self.target is None:
            return
        if math.hypot(self.target[0] - state.x, self.target[1] - state.y) <= self.wp_radius:
            self.reached.append(self.seq)
            self.texts.append((SEVERITY_INFO, f"Reached waypoint #{self.seq}"))
            self._begin(self.seq + 1, state)

    def commands(self, state: RoverState, params: RoverParams,
                 cfg: guidance.GuidanceConfig) -> tuple[float, float]:
        """The plant's own driving outside the guided sub-mode (to the waypoint, or stopped)."""
        if self.complete or self.target is None:
            return 0.0, 0.0
        return guidance.commands(PositionTarget(*self.target), state, params,
                                 replace(cfg, cruise_speed=self.speed, arrive_radius=0.0))

    def pop(self) -> tuple[list[int], list[tuple[int, str]]]:
        reached, texts = self.reached, self.texts
        self.reached, self.texts = [], []
        return reached, texts
