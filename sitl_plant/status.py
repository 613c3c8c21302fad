"""What the plant's autopilot says about its estimate and arming: EKF_STATUS_REPORT, the
SYS_STATUS pre-arm bit, the PreArm text (the origin itself is :mod:`sitl_plant.earth`'s).

The plant's pose is exact, so its EKF is healthy from ``--ekf-delay`` seconds of vehicle time on
(and not before its origin is set, ``--origin-delay``; ArduPilot SITL: about 20 s to an origin,
40 s to arming). Before that it has an attitude and nothing else, and the pre-arm checks fail,
as SITL's do until its EKF runs. Pure: the server sends.
"""

from __future__ import annotations

from dataclasses import dataclass

MSG_EKF_STATUS_REPORT = 193
MAV_CMD_RUN_PREARM_CHECKS = 401
PREARM_BIT = 0x10000000                 # MAV_SYS_STATUS_PREARM_CHECK
# EKF_ATTITUDE | VELOCITY_HORIZ | VELOCITY_VERT | POS_HORIZ_REL | POS_HORIZ_ABS | POS_VERT_ABS
# | PRED_POS_HORIZ_REL | PRED_POS_HORIZ_ABS: 0x33f, what ArduPilot SITL reports once settled
EKF_GOOD = 0x33F
EKF_ATTITUDE_ONLY = 0x1
PREARM_TEXT = "PreArm: AHRS: not using configured AHRS type"   # as the plant's arming refusal


@dataclass(frozen=True)
class EkfReport:
    flags: int
    velocity_variance: float
    pos_horiz_variance: float
    pos_vert_variance: float
    compass_variance: float


def ekf_ready(t: float, ekf_delay: float) -> bool:
    return t >= ekf_delay


def ekf_report(t: float, ekf_delay: float) -> EkfReport:
    if ekf_ready(t, ekf_delay):
        return EkfReport(EKF_GOOD, 0.01, 0.01, 0.01, 0.02)
    return EkfReport(EKF_ATTITUDE_ONLY, 0.0, 0.0, 0.0, 0.0)


def sensors(can_arm: bool) -> tuple[int, int, int]:
    """SYS_STATUS present / enabled / health: only the pre-arm bit is modelled."""
    return PREARM_BIT, PREARM_BIT, PREARM_BIT if can_arm else 0
