"""What the plant's autopilot says about its estimate and arming: EKF_STATUS_REPORT, the
SYS_STATUS pre-arm bit, the PreArm text (the origin itself is :mod:`sitl_plant.earth`'s).

The plant's pose is exact, so its EKF is healthy from ``--ekf-delay`` seconds of vehicle time on
(and not before its origin is set, ``--origin-delay``; ArduPilot SITL: about 20 s to an origin,
40 s to arming). Before that it has an attitude and nothing else, and the pre-arm checks fail,
as SITL's do until its EKF runs. Pure: the server sends.

GPS faults (``--gps-glitch``, ``--gps-loss``, ``--gps-float``; :class:`GpsFault`) imitate what ArduPilot SITL's
EKF reports for SIM_GPS1_GLTCH_X / _Y and SIM_GPS1_ENABLE 0 (docs/field-faults.md): a glitch
sets EKF_GPS_GLITCHING (0x833f) and moves LOCAL_POSITION_NED by its size (north) for its
duration, as the fall-back to a glitched fix does; a loss drops the absolute position (0x27)
while the pose stays true (dead reckoning on an exact plant); RTK float moves it by its size
(north) with the EKF healthy, GPS_RAW_INT saying fix type 5 (:func:`gps_raw`); a multipath
jump moves GPS_RAW_INT's position at once and LOCAL_POSITION_NED over ``EKF_SLIDE``, the
receiver still "fixed". The plant has no EKF failsafe of
its own: the companion's reaction is what these test.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

MSG_EKF_STATUS_REPORT = 193
MAV_CMD_RUN_PREARM_CHECKS = 401
PREARM_BIT = 0x10000000                 # MAV_SYS_STATUS_PREARM_CHECK
BATTERY_BIT = 0x2000000                 # MAV_SYS_STATUS_SENSOR_BATTERY
# EKF_ATTITUDE | VELOCITY_HORIZ | VELOCITY_VERT | POS_HORIZ_REL | POS_HORIZ_ABS | POS_VERT_ABS
# | PRED_POS_HORIZ_REL | PRED_POS_HORIZ_ABS: 0x33f, what ArduPilot SITL reports once settled
EKF_GOOD = 0x33F
EKF_ATTITUDE_ONLY = 0x1
PREARM_TEXT = "PreArm: AHRS: not using configured AHRS type"   # as the plant's arming refusal


EKF_GLITCHING = 0x833F                 # EKF_GOOD | EKF_GPS_GLITCHING (0x8000)
EKF_NO_GPS = 0x27                      # attitude, velocities, relative position, vertical
EKF_NO_ORIGIN = 0x12F                   # EKF_GOOD without absolute horizontal position (0x10,
                                        # 0x200): a local estimate, no origin (no GPS)


@dataclass(frozen=True)
class GpsFault:
    kind: str            # "glitch", "loss", "float" or "jump"
    at: float            # vehicle s
    duration: float      # s
    size: float = 14.0   # m north (a glitch's or a float's offset in LOCAL_POSITION_NED)

    def active(self, t: float) -> bool:
        return self.at <= t < self.at + self.duration


EKF_SLIDE = 0.7          # s: the time constant the plant's EKF follows a receiver's jump with


def position_offset(t: float, faults: tuple[GpsFault, ...]) -> float:
    """Metres north the estimate is off the truth at vehicle time ``t``: a glitch's or a
    float's size while it lasts; a jump's slid into (and, after it, out of) over EKF_SLIDE, as
    ArduPilot's EKF follows a "fixed" receiver that multipath moved."""
    total = sum(f.size for f in faults if f.kind in ("glitch", "float") and f.active(t))
    for f in faults:
        if f.kind != "jump" or t < f.at:
            continue
        inside = min(t, f.at + f.duration) - f.at
        slid = f.size * (1.0 - math.exp(-inside / EKF_SLIDE))
        total += slid * math.exp(-max(0.0, t - f.at - f.duration) / EKF_SLIDE)
    return total


def receiver_offset(t: float, faults: tuple[GpsFault, ...]) -> float:
    """Metres north GPS_RAW_INT's position is off the truth at ``t``: a jump's size while it
    lasts (multipath moves the receiver at once; the EKF follows it slowly)."""
    return sum(f.size for f in faults if f.kind == "jump" and f.active(t))


# GPS_RAW_INT: the plant's receiver is RTK fixed (its pose is exact) but in a fault
FIX_NONE, FIX_RTK_FLOAT, FIX_RTK_FIXED = 1, 5, 6
H_ACC_FIXED_MM, H_ACC_FLOAT_MM = 14, 400


def gps_raw(t: float, faults: tuple[GpsFault, ...]) -> tuple[int, int]:
    """GPS_RAW_INT's (fix_type, h_acc mm) at vehicle time ``t``: RTK fixed; float (5, 0.4 m)
    in a ``--gps-float``, whose offset the EKF lets into LOCAL_POSITION_NED unflagged, as
    ArduPilot's does (docs/gnss.md); no fix in a ``--gps-loss``. A glitch keeps "fixed" (the
    receiver does not know)."""
    active = {f.kind for f in faults if f.active(t)}
    if "loss" in active:
        return FIX_NONE, 0
    if "float" in active:
        return FIX_RTK_FLOAT, H_ACC_FLOAT_MM
    return FIX_RTK_FIXED, H_ACC_FIXED_MM


@dataclass(frozen=True)
class EkfReport:
    flags: int
    velocity_variance: float
    pos_horiz_variance: float
    pos_vert_variance: float
    compass_variance: float


def ekf_ready(t: float, ekf_delay: float) -> bool:
    return t >= ekf_delay


def ekf_report(t: float, ekf_delay: float, faults: tuple[GpsFault, ...] = (),
               origin_delay: float = 0.0) -> EkfReport:
    if ekf_ready(t, ekf_delay) and not ekf_ready(t, origin_delay):
        return EkfReport(EKF_NO_ORIGIN, 0.01, 0.01, 0.01, 0.02)
    if ekf_ready(t, ekf_delay):
        active = {f.kind for f in faults if f.active(t)}
        if "loss" in active:
            return EkfReport(EKF_NO_GPS, 0.2, 0.5, 0.1, 0.02)
        if "glitch" in active:
            return EkfReport(EKF_GLITCHING, 0.3, 1.2, 0.1, 0.02)
        return EkfReport(EKF_GOOD, 0.01, 0.01, 0.01, 0.02)
    return EkfReport(EKF_ATTITUDE_ONLY, 0.0, 0.0, 0.0, 0.0)


def sensors(can_arm: bool, battery_ok: bool = True) -> tuple[int, int, int]:
    """SYS_STATUS present / enabled / health: the pre-arm bit and the battery monitor's (whose
    health ArduPilot clears when its battery failsafe triggers)."""
    bits = PREARM_BIT | BATTERY_BIT
    return bits, bits, (PREARM_BIT if can_arm else 0) | (BATTERY_BIT if battery_ok else 0)
