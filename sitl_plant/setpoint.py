"""SET_POSITION_TARGET_LOCAL_NED -> a guidance target, the way each autopilot reads it.

ArduPilot Rover (Rover/GCS_MAVLink_Rover.cpp, handle_set_position_target_local_ned): a field
group counts as ignored when ANY of its type_mask bits is set (Rover/defines.h); acceleration must
be ignored or the message is dropped; a position wins; velocity alone is a heading + speed;
velocity with yaw or yaw rate keeps the sign of vx (reverse); velocity with yaw rate is exactly the
paper's (v_ref, omega_ref). PX4 rovers (rover_differential) take a position or a velocity vector
and ignore yaw and yaw rate: the heading follows the velocity direction.

Pure: plain numbers in, a target or a rejection reason out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.core.angles import wrap

FRAME_LOCAL_NED = 1
FRAME_LOCAL_OFFSET_NED = 7
FRAME_BODY_NED = 8
FRAME_BODY_OFFSET_NED = 9
ARDUPILOT_FRAMES = (FRAME_LOCAL_NED, FRAME_LOCAL_OFFSET_NED, FRAME_BODY_NED, FRAME_BODY_OFFSET_NED)
BODY_FRAMES = (FRAME_BODY_NED, FRAME_BODY_OFFSET_NED)
PX4_FRAMES = (FRAME_LOCAL_NED, FRAME_BODY_NED)

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


def _used(mask: int, group: int) -> bool:
    return not (mask & group)


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def _plausible(*values: float, limit: float) -> bool:
    return all(abs(v) <= limit for v in values)


def _body_to_ne(x: float, y: float, yaw: float) -> tuple[float, float]:
    c, s = math.cos(yaw), math.sin(yaw)
    return x * c - y * s, x * s + y * c


def _position(sp: Setpoint, pose: Pose) -> PositionTarget:
    if sp.frame in BODY_FRAMES:
        dn, de = _body_to_ne(sp.x, sp.y, pose.yaw)
        return PositionTarget(pose.x + dn, pose.y + de)
    if sp.frame == FRAME_LOCAL_OFFSET_NED:
        return PositionTarget(pose.x + sp.x, pose.y + sp.y)
    # LOCAL_NED: ArduPilot reads it as an offset from home; the plant's home is the local origin.
    return PositionTarget(sp.x, sp.y)


def decode_ardupilot(sp: Setpoint, pose: Pose, max_speed: float) -> Target | Rejected:
    """ArduPilot Rover's reading of a setpoint (see the module docstring)."""
    if sp.frame not in ARDUPILOT_FRAMES:
        return Rejected("frame")
    mask = sp.type_mask
    pos, vel = _used(mask, POS_IGNORE), _used(mask, VEL_IGNORE)
    yaw, rate = _used(mask, YAW_IGNORE), _used(mask, YAW_RATE_IGNORE)
    if _used(mask, ACC_IGNORE):
        return Rejected("acceleration")
    if ((pos and not _finite(sp.x, sp.y)) or (vel and not _finite(sp.vx, sp.vy))
            or (yaw and not _finite(sp.yaw)) or (rate and not _finite(sp.yaw_rate))):
        return Rejected("non-finite")
    if ((pos and not _plausible(sp.x, sp.y, limit=MAX_TARGET_POSITION))
            or (vel and not _plausible(sp.vx, sp.vy, limit=MAX_TARGET_SPEED))
            or (yaw and abs(sp.yaw) > 100.0)
            or (rate and not _plausible(sp.yaw_rate, limit=MAX_TARGET_RATE))):
        return Rejected("out of range")
    if pos:
        return _position(sp, pose)
    body = sp.frame in BODY_FRAMES
    speed, heading = 0.0, pose.yaw
    if vel:
        speed = min(math.hypot(sp.vx, sp.vy), max_speed)
        heading = math.atan2(sp.vy, sp.vx) + (pose.yaw if body else 0.0)
        if (yaw or rate) and sp.vx < 0.0:
            speed = -speed
    if yaw:
        heading = sp.yaw + (pose.yaw if body else 0.0)
    if rate:
        return TurnRateSpeed(speed, sp.yaw_rate)
    if vel and not yaw and speed == 0.0:
        return STOP  # a zero vector has no direction: stand still rather than turn to north
    if vel or yaw:
        return HeadingSpeed(wrap(heading), speed)
    return Rejected("nothing to do")


def decode_px4(sp: Setpoint, pose: Pose, max_speed: float) -> Target | Rejected:
    """PX4 rover offboard: position (LOCAL_NED) or velocity vector; yaw and yaw rate ignored."""
    if sp.frame not in PX4_FRAMES:
        return Rejected("frame")
    mask = sp.type_mask
    pos, vel = _used(mask, POS_IGNORE), _used(mask, VEL_IGNORE)
    if (pos and not _finite(sp.x, sp.y)) or (vel and not _finite(sp.vx, sp.vy)):
        return Rejected("non-finite")
    if ((pos and not _plausible(sp.x, sp.y, limit=MAX_TARGET_POSITION))
            or (vel and not _plausible(sp.vx, sp.vy, limit=MAX_TARGET_SPEED))):
        return Rejected("out of range")
    if pos and sp.frame == FRAME_LOCAL_NED:
        return PositionTarget(sp.x, sp.y)
    if vel:
        vx, vy = sp.vx, sp.vy
        if sp.frame == FRAME_BODY_NED:
            vx, vy = _body_to_ne(vx, vy, pose.yaw)
        speed = min(math.hypot(vx, vy), max_speed)
        if speed == 0.0:
            return STOP
        return HeadingSpeed(math.atan2(vy, vx), speed)
    return Rejected("nothing to do")
