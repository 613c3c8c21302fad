"""Flight-mode tables of the two autopilot personalities the plant imitates.

ArduPilot Rover puts the mode number straight into ``custom_mode`` (Rover/mode.h). PX4 packs a
main mode and a sub mode: ``custom_mode = main << 16 | sub << 24`` (px4_custom_mode.h). What
the plant does in each mode is deliberately small: GUIDED / OFFBOARD follow setpoints, every
other mode holds still (there is no RC pilot and no mission in the plant).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

# MAV_MODE_FLAG bits (common.xml), kept here so the pure modules need no pymavlink import.
FLAG_CUSTOM_MODE_ENABLED = 1
FLAG_AUTO_ENABLED = 4
FLAG_GUIDED_ENABLED = 8
FLAG_STABILIZE_ENABLED = 16
FLAG_MANUAL_INPUT_ENABLED = 64
FLAG_SAFETY_ARMED = 128

MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_PX4 = 12


class Autopilot(str, Enum):
    ARDUPILOT = "ardupilot"
    PX4 = "px4"


@dataclass(frozen=True)
class Mode:
    name: str
    custom_mode: int
    base_flags: int          # base_mode bits besides CUSTOM_MODE_ENABLED / SAFETY_ARMED
    follows_setpoints: bool  # GUIDED (ArduPilot) or OFFBOARD (PX4)
    settable: bool = True


# ArduPilot Rover (Rover/mode.h; base_mode as in Rover/GCS_Rover.cpp).
_AP_MANUAL, _AP_AUTOPILOT = FLAG_MANUAL_INPUT_ENABLED, FLAG_GUIDED_ENABLED
ARDUPILOT_MODES = {m.custom_mode: m for m in (
    Mode("MANUAL", 0, _AP_MANUAL, False),
    Mode("ACRO", 1, _AP_MANUAL, False),
    Mode("STEERING", 3, _AP_MANUAL, False),
    Mode("HOLD", 4, 0, False),
    Mode("LOITER", 5, _AP_AUTOPILOT, False),
    Mode("FOLLOW", 6, _AP_AUTOPILOT, False),
    Mode("SIMPLE", 7, _AP_MANUAL, False),
    Mode("AUTO", 10, _AP_AUTOPILOT, False),
    Mode("RTL", 11, _AP_AUTOPILOT, False),
    Mode("SMART_RTL", 12, _AP_AUTOPILOT, False),
    Mode("GUIDED", 15, _AP_AUTOPILOT, True),
    Mode("INITIALISING", 16, 0, False, settable=False),
)}
AP_HOLD = 4
AP_GUIDED = 15
AP_INITIAL = 0  # Rover's INITIAL_MODE default: MANUAL (stands still without RC input)


def px4_custom_mode(main: int, sub: int = 0) -> int:
    """PX4's custom_mode word: main mode in bits 16-23, sub mode in bits 24-31."""
    return (int(main) & 0xFF) << 16 | (int(sub) & 0xFF) << 24


_PX4_MAN = FLAG_MANUAL_INPUT_ENABLED | FLAG_STABILIZE_ENABLED
_PX4_AUTO = FLAG_AUTO_ENABLED | FLAG_GUIDED_ENABLED | FLAG_STABILIZE_ENABLED
PX4_MODES = {m.custom_mode: m for m in (
    Mode("MANUAL", px4_custom_mode(1), _PX4_MAN, False),
    Mode("POSCTL", px4_custom_mode(3), _PX4_MAN, False),
    Mode("AUTO_LOITER", px4_custom_mode(4, 3), _PX4_AUTO, False),
    Mode("OFFBOARD", px4_custom_mode(6), _PX4_AUTO, True),
)}
PX4_HOLD = px4_custom_mode(4, 3)
PX4_OFFBOARD = px4_custom_mode(6)
PX4_INITIAL = px4_custom_mode(1)


def mode_table(autopilot: Autopilot) -> dict[int, Mode]:
    return ARDUPILOT_MODES if autopilot is Autopilot.ARDUPILOT else PX4_MODES


def initial_mode(autopilot: Autopilot) -> int:
    return AP_INITIAL if autopilot is Autopilot.ARDUPILOT else PX4_INITIAL


def hold_mode(autopilot: Autopilot) -> int:
    return AP_HOLD if autopilot is Autopilot.ARDUPILOT else PX4_HOLD


def heartbeat_autopilot(autopilot: Autopilot) -> int:
    return MAV_AUTOPILOT_ARDUPILOTMEGA if autopilot is Autopilot.ARDUPILOT else MAV_AUTOPILOT_PX4


def base_mode(mode: Mode, armed: bool) -> int:
    return FLAG_CUSTOM_MODE_ENABLED | mode.base_flags | (FLAG_SAFETY_ARMED if armed else 0)


def requested_custom_mode(autopilot: Autopilot, param2: float, param3: float) -> int | None:
    """The custom_mode a MAV_CMD_DO_SET_MODE asks for (param2 = mode / PX4 main, param3 = PX4 sub)."""
    try:
        main, sub = int(param2), int(param3)
    except (ValueError, OverflowError):  # NaN / inf parameters
        return None
    if autopilot is Autopilot.ARDUPILOT:
        return main
    if not (0 <= main <= 0xFF and 0 <= sub <= 0xFF):
        return None                      # would alias another mode once packed
    return px4_custom_mode(main, sub)
