"""A made-up third autopilot, "Acme": everything a new autopilot brings, in one module.

This is what ``companion/profiles/acme.py`` would be (with one line in ``AUTOPILOTS``,
``companion/profiles/__init__.py``); ``tests/profiles/test_profiles_registry.py`` registers it for a test
and flies it through the companion's link, the plant and preflight, touching no other file.
Acme differs from both real ones on purpose: it takes u_p *and* a turn rate in LOCAL_NED and
drives the turn rate at the vector's speed; its frame is one parameter (ACME_STEER: 0 skid,
1 Ackermann); its failsafe for a silent companion is ACME_FS_TIME seconds, then Hold.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from companion.core.signals import Command
from companion.profiles.autopilot import (
    MAV_FRAME_LOCAL_NED,
    MAV_RESULT_DENIED,
    PARAM_INT8,
    PARAM_REAL32,
    AutopilotProfile,
    EstimateFacts,
    FailsafeFacts,
    IdentFacts,
    Mode,
    ModeTable,
    PlantFacts,
    PreflightFacts,
)
from companion.profiles.observed import FAIL, OK, WARN, Check, Observed, missing
from companion.profiles.priors import Priors, defaults
from companion.profiles.setpoint import (
    MAX_TARGET_SPEED,
    Pose,
    Rejected,
    Setpoint,
    SetpointEncoding,
    Target,
    TurnRateSpeed,
    all_finite,
)
from companion.profiles.steering import SteeringProfile

MAV_AUTOPILOT_ACME = 42
MODES = ModeTable((Mode("MANUAL", 0), Mode("HOLD", 1), Mode("FOLLOW", 2)))
STEER = {0: "skid", 1: "ackermann"}       # ACME_STEER -> steering profile name
MASK = 0b0000_0101_1110_0111              # vx, vy and yaw rate used: 1511


# --------------------------------------------------------------------------- setpoints

def encode_setpoint(cmd: Command) -> tuple[float, float, float]:
    """u_p and the turn rate, all three."""
    return cmd.ux, cmd.uy, cmd.yaw_rate


def decode_setpoint(sp: Setpoint, pose: Pose, max_speed: float) -> Target | Rejected:
    """Acme drives the turn rate at the vector's speed; anything but its own mask is refused."""
    if sp.frame != MAV_FRAME_LOCAL_NED or sp.type_mask != MASK:
        return Rejected("frame")
    if not all_finite(sp.vx, sp.vy, sp.yaw_rate):
        return Rejected("non-finite")
    speed = math.hypot(sp.vx, sp.vy)
    if speed > MAX_TARGET_SPEED:
        return Rejected("out of range")
    return TurnRateSpeed(min(speed, max_speed), sp.yaw_rate)


# --------------------------------------------------------------------------- preflight

@dataclass(frozen=True)
class SteerParam:
    """ACME_STEER names the steering kind."""

    param: str = "ACME_STEER"

    def params(self) -> tuple[str, ...]:
        return (self.param,)

    def steering(self, values: Mapping[str, float]) -> SteeringProfile | None:
        from companion import profiles
        value = values.get(self.param)
        return profiles.STEERING.get(STEER.get(int(value), "")) if value is not None else None

    def check(self, obs: Observed) -> list[Check]:
        absent = missing(self.param, obs, "0 (skid)", "it names the steering kind")
        if absent:
            return [absent]
        kind = self.steering(obs.params)
        if kind is None:
            return [Check(self.param, FAIL, f"{obs.params[self.param]:g}", "0 or 1", "unknown")]
        return [Check(self.param, kind.verdict, kind.label, "0 (skid)", kind.why)]


@dataclass(frozen=True)
class SilenceTimer:
    """ACME_FS_TIME s after the last setpoint, Acme holds."""

    param: str = "ACME_FS_TIME"

    def check(self, obs: Observed) -> list[Check]:
        absent = missing(self.param, obs, "1 s or less", "how long Acme drives blind")
        if absent:
            return [absent]
        t = obs.params[self.param]
        ok = 0 < t <= 1.0
        return [Check(self.param, OK if ok else WARN, f"{t:g} s", "0 < t <= 1 s",
                      "Acme holds this long after the companion falls silent",
                      {} if ok else {self.param: 1.0})]


# --------------------------------------------------------------------------- the plant

def plant_params(vehicle, loop_rate: float, sysid: int,
                 offboard_loss_timeout: float) -> list[tuple[str, float, int]]:
    return [("ACME_STEER", 0, PARAM_INT8), ("ACME_FS_TIME", offboard_loss_timeout, PARAM_REAL32)]


PROFILE = AutopilotProfile(
    name="acme", label="Acme",
    mav_autopilot=(MAV_AUTOPILOT_ACME,),
    modes=MODES, mode_types=None,
    track_mode="FOLLOW", hold_mode="HOLD",
    set_mode_params=lambda mode: (1.0, float(mode.custom_mode), 0.0),
    requested_mode=lambda p2, p3: int(p2) if math.isfinite(p2) else None,
    mode_name=lambda table, base, custom: getattr(table.by_number(custom), "name", "UNKNOWN"),
    setpoint=SetpointEncoding(frame=MAV_FRAME_LOCAL_NED, type_mask=MASK, velocity_vector=False,
                              encode=encode_setpoint, decode=decode_setpoint),
    offboard_warmup=None,
    bytewise_params=False,
    preflight=PreflightFacts(frame=SteerParam(), failsafe=SilenceTimer(), loop_rate_param=None,
                             limits=(), top_speed=None, limits_unread="Acme has no limits",
                             estimator_messages=("EKF_STATUS_REPORT",), prearm_command=False),
    ident=IdentFacts(params=("ACME_STEER",), priors=lambda values: Priors(defaults(), {}),
                     headroom=1.0, params_label="Acme"),
    plant=PlantFacts(modes=("MANUAL", "HOLD", "FOLLOW"), unsettable=(), initial_mode="MANUAL",
                     mode_refused=MAV_RESULT_DENIED, arm_texts=("Acme armed", "Acme disarmed"),
                     tick_aligned=False, params=plant_params),
    # its failsafe report: what its texts mean
    failsafe=FailsafeFacts(texts=(("acme lost you", "gcs"), ("acme battery", "battery")),
                           cleared=("acme fine",)),
    estimate=EstimateFacts(message="EKF_STATUS_REPORT", message_id=193, flags_field="flags",
                           need=((0x08, "no relative position"),), bad=(), variances=()),
)
