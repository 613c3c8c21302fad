"""Flight modes as the plant has them: the autopilot profile's mode table, cut to the modes the plant emulates.

The numbers, names and ``base_mode`` bits are the profile's (:mod:`companion.profiles`: ArduPilot
Rover puts the mode number straight into ``custom_mode``, PX4 packs a main and a sub mode), and
so are the modes the plant has of them (``PlantFacts.modes``), the ones it refuses to enter and
the one it boots in. What the plant does in each mode is deliberately small: the profile's track
mode (GUIDED / OFFBOARD) follows setpoints, every other mode holds still (there is no RC pilot
and no mission in the plant).
"""

from __future__ import annotations

from dataclasses import dataclass

from companion.profiles.autopilot import (  # noqa: F401
    FLAG_AUTO_ENABLED,
    FLAG_CUSTOM_MODE_ENABLED,
    FLAG_GUIDED_ENABLED,
    FLAG_MANUAL_INPUT_ENABLED,
    FLAG_SAFETY_ARMED,
    FLAG_STABILIZE_ENABLED,
    AutopilotProfile,
)


@dataclass(frozen=True)
class Mode:
    name: str
    custom_mode: int
    base_flags: int          # base_mode bits besides CUSTOM_MODE_ENABLED / SAFETY_ARMED
    follows_setpoints: bool  # the profile's track mode
    settable: bool = True


def mode_table(autopilot: AutopilotProfile) -> dict[int, Mode]:
    """custom_mode -> Mode, for the modes the plant emulates of this autopilot."""
    facts = autopilot.plant
    return {m.custom_mode: Mode(m.name, m.custom_mode, m.base_flags,
                                follows_setpoints=m.name == autopilot.track_mode,
                                settable=m.name not in facts.unsettable)
            for m in autopilot.modes.modes if m.name in facts.modes}


def initial_mode(autopilot: AutopilotProfile) -> int:
    return autopilot.mode_number(autopilot.plant.initial_mode)


def hold_mode(autopilot: AutopilotProfile) -> int:
    return autopilot.mode_number(autopilot.hold_mode)


def base_mode(mode: Mode, armed: bool) -> int:
    return FLAG_CUSTOM_MODE_ENABLED | mode.base_flags | (FLAG_SAFETY_ARMED if armed else 0)
