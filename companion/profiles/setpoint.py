"""SET_POSITION_TARGET_LOCAL_NED both ways: what an autopilot profile's setpoint encoding is, and the targets a reading of one gives.

Each autopilot profile (``ardupilot.py``, ``px4.py``) says how the tracker's command goes out
(:class:`SetpointEncoding` ``encode``: the companion's link sends it) and how the autopilot reads
such a message (``decode``: ``sitl_plant`` drives its rover by it). What every reading shares
lives here: the message's fields the plant looks at (:class:`Setpoint`), the vehicle's pose when it
arrives (:class:`Pose`, for offset and body frames), the guidance targets a reading gives
(:class:`TurnRateSpeed`, :class:`HeadingSpeed`, :class:`PositionTarget`) or its rejection, the
type_mask's field groups (as Rover/defines.h groups them: a group counts as ignored when ANY of
its bits is set) and the plausibility bounds.

Pure: plain numbers in, a target or a rejection reason out.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from ..core.signals import Command

FRAME_LOCAL_NED = 1
FRAME_LOCAL_OFFSET_NED = 7
FRAME_BODY_NED = 8
FRAME_BODY_OFFSET_NED = 9
BODY_FRAMES = (FRAME_BODY_NED, FRAME_BODY_OFFSET_NED)

# Field groups of type_mask (POSITION_TARGET_TYPEMASK bits, grouped as in Rover/defines.h).
POS_IGNORE = 0b11            # x, y
VEL_IGNORE = 0b11 << 3       # vx, vy
ACC_IGNORE = 0b11 << 6       # afx, afy
YAW_IGNORE = 1 << 10
YAW_RATE_IGNORE = 1 << 11


@dataclass(frozen=True)
class Setpoint:
    """The fields of one SET_POSITION_TARGET_LOCAL_NED the plant looks at."""

    frame: int
    type_mask: int
    x: float = 0.0
    y: float = 0.0
    vx: float = 0.0
    vy: float = 0.0
    afx: float = 0.0
    afy: float = 0.0
    yaw: float = 0.0
    yaw_rate: float = 0.0


@dataclass(frozen=True)
class TurnRateSpeed:
    """Drive at ``speed`` (negative: reverse) turning at ``yaw_rate``; times out."""

    speed: float
    yaw_rate: float


@dataclass(frozen=True)
class HeadingSpeed:
    """Turn towards ``heading`` and drive at ``speed``; times out."""

    heading: float
    speed: float


@dataclass(frozen=True)
class PositionTarget:
    """Drive to (x, y) and stop there; never times out."""

    x: float
    y: float


Target = TurnRateSpeed | HeadingSpeed | PositionTarget
STOP = TurnRateSpeed(0.0, 0.0)


@dataclass(frozen=True)
class Rejected:
    reason: str  # "frame", "acceleration", "non-finite", "out of range", "nothing to do"


# Beyond these no rover goes: a field this large is corrupted or forged, and the paper's plant
# (no speed limit of its own) would otherwise obey it. A real autopilot clamps to WP_SPEED.
MAX_TARGET_POSITION = 1.0e6   # m
MAX_TARGET_SPEED = 100.0      # m/s
MAX_TARGET_RATE = 100.0       # rad/s


@dataclass(frozen=True)
class Pose:
    """Where the vehicle is when the setpoint arrives (for offset and body frames)."""

    x: float
    y: float
    yaw: float


def used(mask: int, group: int) -> bool:
    return not (mask & group)


def all_finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def plausible(*values: float, limit: float) -> bool:
    return all(abs(v) <= limit for v in values)


def body_to_ne(x: float, y: float, yaw: float) -> tuple[float, float]:
    c, s = math.cos(yaw), math.sin(yaw)
    return x * c - y * s, x * s + y * c


def position(sp: Setpoint, pose: Pose) -> PositionTarget:
    if sp.frame in BODY_FRAMES:
        dn, de = body_to_ne(sp.x, sp.y, pose.yaw)
        return PositionTarget(pose.x + dn, pose.y + de)
    if sp.frame == FRAME_LOCAL_OFFSET_NED:
        return PositionTarget(pose.x + sp.x, pose.y + sp.y)
    # LOCAL_NED: ArduPilot reads it as an offset from home; the plant's home is the local origin.
    return PositionTarget(sp.x, sp.y)


# --------------------------------------------------------------------------- an autopilot's encoding

@dataclass(frozen=True)
class SetpointEncoding:
    """How the tracker's command goes out as SET_POSITION_TARGET_LOCAL_NED, and how the
    autopilot reads such a message.

    ``encode(command)`` gives (vx, vy, yaw_rate), sent in ``frame`` with ``type_mask`` (the
    rest zero); ``decode(setpoint, pose, max_speed)`` is the autopilot's reading of any such
    message: a guidance target, or why it is refused. ``velocity_vector`` True: (vx, vy) = u_p,
    the autopilot ignores yaw and yaw rate and steers along the velocity itself; False:
    (vx, vy, yaw_rate) = (v_ref, 0, omega_ref), the paper's two inputs (read by the profiles
    only: the tuner's settings, the priors' model)."""

    frame: int
    type_mask: int
    velocity_vector: bool
    encode: Callable[[Command], tuple[float, float, float]]
    decode: Callable[[Setpoint, Pose, float], Target | Rejected]
