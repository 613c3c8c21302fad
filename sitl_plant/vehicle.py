"""The simulated autopilot: mode / arming / guided-target state machine around the rover model.

Pure and clock-free: the caller says how far to step (``step(dt)``), when a command or setpoint
arrives, and drains :attr:`Vehicle.texts` (the STATUSTEXTs an autopilot would send). The rover's
motion is :class:`companion.sim.plant.RoverModel` (the paper's eqs. (1)-(2) with first-order
actuators); this module only decides which (speed, turn-rate) commands it gets.

Which autopilot it imitates is a profile (:mod:`companion.profiles`), and the profile answers
every question that differs: an autopilot that needs an offboard warm-up (PX4) only enters its
track mode after proof of life, watches the setpoint stream in any mode and leaves the track mode
for its hold mode when the stream stops for COM_OF_LOSS_T; one without (ArduPilot) takes targets
only in GUIDED and armed, forgets them on a mode change or disarming, and drops a speed /
turn-rate or heading target 3 s after the last one arrived (Rover/mode_guided.cpp). Setpoints
are read as the profile reads them (``setpoint.decode``); refusals, ACK results and texts are
the profile's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import companion.profiles as profiles
from companion.core.angles import wrap
from companion.profiles.autopilot import AutopilotProfile
from companion.profiles.setpoint import (
    STOP,
    HeadingSpeed,
    Pose,
    PositionTarget,
    Rejected,
    Setpoint,
    Target,
)
from companion.sim.plant import RoverModel, RoverParams, RoverState

from . import guidance, modes

GUIDED_TIMEOUT_TEXT = "target not received last 3secs, stopping"
ARM_REFUSED_TEXT = "Arm: AHRS: not using configured AHRS type"
OFFBOARD_REFUSED_TEXT = "Offboard denied: no setpoint stream"
OFFBOARD_LOST_TEXT = "Offboard signal lost, switching to Hold"

# MAVLink severities used in STATUSTEXT.
SEVERITY_WARNING = 4
SEVERITY_NOTICE = 5
SEVERITY_INFO = 6


class Result(IntEnum):
    """MAV_RESULT values for COMMAND_ACK."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4


@dataclass(frozen=True)
class VehicleConfig:
    params: RoverParams = field(default_factory=RoverParams.paper)
    autopilot: AutopilotProfile = profiles.autopilot_named(profiles.DEFAULT_AUTOPILOT)
    arm_delay: float = 0.0                  # s of vehicle time during which arming is refused
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)  # x north, y east, yaw
    guidance: guidance.GuidanceConfig = field(default_factory=guidance.GuidanceConfig)
    guided_timeout: float = 3.0             # ArduPilot: speed/turn-rate and heading targets
    offboard_loss_timeout: float = 0.5      # PX4 COM_OF_LOSS_T
    proof_of_life_time: float = 1.0         # PX4: stream must have run this long ...
    proof_of_life_gap: float = 0.5          # ... with no gap longer than this (> 2 Hz)


class Vehicle:
    """One rover and its autopilot. Times are seconds of vehicle time since boot."""

    def __init__(self, config: VehicleConfig = VehicleConfig()):
        self.config = config
        self.model = RoverModel(config.params)
        x, y, yaw = config.start
        self.state = RoverState(x=x, y=y, yaw=wrap(yaw))
        self.t_us = 0   # integer microseconds: timers compare exactly, long runs do not drift
        self.autopilot = config.autopilot
        # PX4-like: proof of life before the track mode, the stream watched in every mode
        self._offboard = config.autopilot.offboard_warmup is not None
        self._modes = modes.mode_table(config.autopilot)
        self.custom_mode = modes.initial_mode(config.autopilot)
        self.armed = False
        self.target: Target | None = None
        self._target_time = 0.0
        self._target_fresh = False                 # ArduPilot: not yet timed out
        self._last_setpoint: float | None = None   # any setpoint for us, PX4 proof of life
        self._stream_start: float | None = None
        self.texts: list[tuple[int, str]] = []
        self.setpoints_used = 0
        self.setpoints_ignored: dict[str, int] = {}
        self.auto: Any = None      # sitl_plant.auto.Auto: the stored mission in AUTO (the server's)

    @property
    def in_auto(self) -> bool:
        return self.auto is not None and self.mode.name == self.autopilot.auto_mode

    @property
    def takes_setpoints(self) -> bool:
        """In the track mode, or in AUTO's guided sub-mode (NAV_GUIDED_ENABLE)."""
        return self.mode.follows_setpoints or (self.in_auto and self.auto.guided)

    # --- what the heartbeat reports -------------------------------------------------------
    @property
    def mode(self) -> modes.Mode:
        return self._modes[self.custom_mode]

    @property
    def base_mode(self) -> int:
        return modes.base_mode(self.mode, self.armed)

    def commands(self) -> tuple[float, float]:
        """(speed, yaw rate) the autopilot asks of the actuators right now."""
        if self.armed and self.in_auto and not self.auto.guided:
            return self.auto.commands(self.state, self.config.params, self.config.guidance)
        if not (self.armed and self.takes_setpoints):
            return 0.0, 0.0
        return guidance.commands(self.target, self.state, self.config.params,
                                 self.config.guidance)

    # --- commands ---------------------------------------------------------------------------
    def set_mode(self, custom_mode: int | None) -> Result:
        mode = self._modes.get(custom_mode) if custom_mode is not None else None
        if mode is None or not mode.settable:
            self._say(SEVERITY_WARNING, f"Invalid mode: {custom_mode}")
            return Result(self.autopilot.plant.mode_refused)
        if custom_mode == self.custom_mode:
            return Result.ACCEPTED
        if self._offboard and mode.follows_setpoints and not self._proof_of_life():
            self._say(SEVERITY_WARNING, OFFBOARD_REFUSED_TEXT)
            return Result.DENIED
        auto = mode.name == self.autopilot.auto_mode and self.auto is not None
        if auto and not self.auto.can_start():
            self._say(SEVERITY_NOTICE, "No Mission. Can't set AUTO.")
            return Result.FAILED
        self._enter(mode)
        if auto:
            self.auto.start(self.state)
        return Result.ACCEPTED

    def arm(self, on: bool) -> Result:
        if on == self.armed:
            return Result.ACCEPTED
        if on and self.t < self.config.arm_delay:
            self._say(SEVERITY_WARNING, ARM_REFUSED_TEXT)
            return Result.TEMPORARILY_REJECTED
        self.armed = on
        if not on and not self._offboard:
            self.target, self._target_fresh = None, False
        armed_text, disarmed_text = self.autopilot.plant.arm_texts
        self._say(SEVERITY_INFO, armed_text if on else disarmed_text)
        return Result.ACCEPTED

    def setpoint(self, sp: Setpoint) -> str:
        """Handle one SET_POSITION_TARGET_LOCAL_NED addressed to us; returns what became of it."""
        if self._offboard:
            self._note_stream()
        elif not (self.armed and self.takes_setpoints):
            return self._ignored("not guided and armed")
        pose = Pose(self.state.x, self.state.y, self.state.yaw)
        target = self.autopilot.setpoint.decode(sp, pose, self.config.params.max_speed)
        if isinstance(target, Rejected):
            return self._ignored(target.reason)
        self.target, self._target_time, self._target_fresh = target, self.t, True
        self.setpoints_used += 1
        return "used"

    # --- time -------------------------------------------------------------------------------
    def step(self, dt: float) -> None:
        """Advance ``dt`` seconds: timers first (they act on this instant), then the dynamics."""
        if self.in_auto and self.armed:
            was_guided = self.auto.guided
            self.auto.step(self.state)
            if self.auto.guided and not was_guided:
                self.target, self._target_fresh = None, False   # the guided sub-mode starts stopped
        if self.takes_setpoints:
            if self._offboard:
                self._offboard_loss()
            else:
                self._guided_timeout()
        speed, rate = self.commands()
        # A vehicle model with PX4's course loop takes the velocity vector as PX4 gets it (no
        # pivot: an Ackermann rover drives its turning circle); other targets (a stop, a
        # position) as the vector that asks for that turn rate (RoverModel.step_command).
        target, vector = self.target, None
        if self.armed and self.takes_setpoints and isinstance(target, HeadingSpeed):
            vector = (target.speed * math.cos(target.heading),
                      target.speed * math.sin(target.heading))
        s = self.model.step_command(self.state, speed, rate, dt, vector)
        if not -math.pi < s.yaw <= math.pi:
            s.yaw = wrap(s.yaw)
        self.state = s
        self.t_us += int(round(dt * 1e6))

    @property
    def t(self) -> float:
        """Seconds of vehicle time since boot."""
        return self.t_us * 1e-6

    def velocity(self) -> tuple[float, float]:
        """Eq. (1): the tracked point's velocity (LOCAL_POSITION_NED vx, vy)."""
        return self.model.velocity(self.state)

    # --- internals --------------------------------------------------------------------------
    def _enter(self, mode: modes.Mode) -> None:
        self.custom_mode = mode.custom_mode
        if not self._offboard:
            # entering GUIDED starts stopped; other modes hold still
            self.target, self._target_fresh = None, False
        self._say(SEVERITY_INFO, f"Mode changed to {mode.name}")

    def _guided_timeout(self) -> None:
        if (self._target_fresh and not isinstance(self.target, PositionTarget)
                and self.t - self._target_time >= self.config.guided_timeout - 1e-9):
            self.target, self._target_fresh = STOP, False
            self._say(SEVERITY_WARNING, GUIDED_TIMEOUT_TEXT)

    def _offboard_loss(self) -> None:
        last = self._last_setpoint
        if last is None or self.t - last > self.config.offboard_loss_timeout:
            self._enter(self._modes[modes.hold_mode(self.autopilot)])
            self._say(SEVERITY_WARNING, OFFBOARD_LOST_TEXT)

    def _note_stream(self) -> None:
        last = self._last_setpoint
        if last is None or self.t - last > self.config.proof_of_life_gap:
            self._stream_start = self.t
        self._last_setpoint = self.t

    def _proof_of_life(self) -> bool:
        last, start = self._last_setpoint, self._stream_start
        return (last is not None and start is not None
                and self.t - last <= self.config.proof_of_life_gap
                and self.t - start >= self.config.proof_of_life_time - 1e-9)

    def _ignored(self, reason: str) -> str:
        self.setpoints_ignored[reason] = self.setpoints_ignored.get(reason, 0) + 1
        return reason

    def _say(self, severity: int, text: str) -> None:
        self.texts.append((severity, text))

    def pop_texts(self) -> list[tuple[int, str]]:
        texts, self.texts = self.texts, []
        return texts
