"""What an autopilot profile says: everything the companion and the plant do differently per autopilot.

One :class:`AutopilotProfile` per autopilot (``ardupilot.py``, ``px4.py``), registered in
``companion/profiles/__init__.py``. Code outside ``companion/profiles/`` never asks which
autopilot it talks to; it reads the answer from the profile (``tests/profiles/test_profiles.py`` reads
the code for any test of an autopilot's name). The profile holds facts and the behaviour that
differs (a frontend calls it, one backend per autopilot), no I/O:

* ids: the HEARTBEAT's MAV_AUTOPILOT value(s);
* modes: the mode table (pymavlink's names <-> HEARTBEAT ``custom_mode`` and ``base_mode``), the
  mode that follows the companion's setpoints and the one it hands the vehicle back in, how
  MAV_CMD_DO_SET_MODE asks for a mode and how a heartbeat names one;
* the setpoint encoding of SET_POSITION_TARGET_LOCAL_NED (frame, type mask, speed and yaw rate
  or the velocity vector u_p: :class:`~companion.profiles.setpoint.SetpointEncoding`, which also
  reads such a message as the autopilot does, for the plant) and the offboard warm-up (setpoints streamed before the track mode
  is asked for; None: none needed);
* the parameter protocol's encoding (bytewise or C cast);
* the preflight facts (:class:`PreflightFacts`: parameter names and the values the checks want,
  and the autopilot's own checks of its frame and its failsafe, ``frame.check`` /
  ``failsafe.check``);
* the identification facts (:class:`IdentFacts`: the parameters read, the priors made of them,
  the manoeuvre's headroom);
* what ``sitl_plant`` emulates differently (:class:`PlantFacts`);
* how its own failsafes show and how its estimator reports its health (:class:`FailsafeFacts`,
  :class:`EstimateFacts`): what the companion reads to tell the autopilot's failsafe from a pilot;
* what a drop in the receiver's class does (:class:`~companion.profiles.gnss.GnssPolicy`).

Pure: no pymavlink (the MAVLink numbers it needs are spelled out below, checked against
pymavlink's by ``tests/profiles/test_profiles.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from .gnss import GnssPolicy
from .priors import Priors
from .setpoint import SetpointEncoding

if TYPE_CHECKING:
    from .observed import Check, Observed
    from .steering import SteeringProfile

# MAVLink numbers (common.xml), here so the profiles need no pymavlink.
MAV_SYS_STATUS_SENSOR_BATTERY = 0x2000000
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_PX4 = 12
MAV_TYPE_GROUND_ROVER, MAV_TYPE_SURFACE_BOAT = 10, 11
MAV_FRAME_LOCAL_NED, MAV_FRAME_BODY_NED = 1, 8
FLAG_CUSTOM_MODE_ENABLED = 1
FLAG_AUTO_ENABLED = 4
FLAG_GUIDED_ENABLED = 8
FLAG_STABILIZE_ENABLED = 16
FLAG_MANUAL_INPUT_ENABLED = 64
FLAG_SAFETY_ARMED = 128
MAV_RESULT_DENIED, MAV_RESULT_FAILED = 2, 4
PARAM_INT8, PARAM_INT16, PARAM_INT32, PARAM_REAL32 = 2, 4, 6, 9


# --------------------------------------------------------------------------- modes

@dataclass(frozen=True)
class Mode:
    name: str            # pymavlink's name (what the companion logs and asks for)
    custom_mode: int     # HEARTBEAT.custom_mode
    base_flags: int = 0  # HEARTBEAT.base_mode bits besides CUSTOM_MODE_ENABLED and SAFETY_ARMED


@dataclass(frozen=True)
class ModeTable:
    """An autopilot's flight modes, by name and by number."""

    modes: tuple[Mode, ...] = ()

    def by_name(self, name: str) -> Mode | None:
        return next((m for m in self.modes if m.name == name), None)

    def by_number(self, custom_mode: int) -> Mode | None:
        return next((m for m in self.modes if m.custom_mode == custom_mode), None)

    def names(self) -> frozenset[str]:
        return frozenset(m.name for m in self.modes)


# --------------------------------------------------------------------------- preflight facts

class SteeringFrame(Protocol):
    """How the autopilot's setup shows the steering kind (ArduPilot's output functions:
    :class:`~companion.profiles.ardupilot_preflight.ServoFrame`; PX4's airframe parameter:
    :class:`~companion.profiles.px4.AirframeFrame`)."""

    def params(self) -> tuple[str, ...]:
        """The parameters that tell the steering kind."""
        ...

    def steering(self, values: Mapping[str, float]) -> SteeringProfile | None:
        """The steering kind those parameters (``{name: value}``) show, None if none."""
        ...

    def check(self, obs: Observed) -> list[Check]:
        """Preflight's rows on the frame and its steering kind."""
        ...


class SilenceFailsafe(Protocol):
    """The autopilot's failsafe for a companion that falls silent (ArduPilot's GCS failsafe:
    :class:`~companion.profiles.ardupilot_preflight.GcsFailsafe`; PX4's offboard loss:
    :class:`~companion.profiles.px4.OffboardFailsafe`)."""

    def check(self, obs: Observed) -> list[Check]:
        """Preflight's rows on that failsafe's parameters."""
        ...


@dataclass(frozen=True)
class LimitParam:
    """One inner-loop limit parameter, as the vehicle model reads it."""

    name: str
    unit: str
    to_si: float
    field: str                          # companion.profiles.observed.Limits field
    what: str
    zero_as: str | None = None          # 0 means "as this parameter" (None: 0 is no limit)


@dataclass(frozen=True)
class TopSpeedParams:
    """Top speed = the waypoint speed, no faster than full throttle (cruise speed scaled)."""

    wp_speed: str
    cruise_speed: str
    cruise_throttle: str


@dataclass(frozen=True)
class PreflightFacts:
    frame: SteeringFrame                 # its ``check``: preflight's steering rows
    failsafe: SilenceFailsafe            # its ``check``: preflight's failsafe rows
    loop_rate_param: str | None         # a stream above 0.8 x it is refused (None: no such cap)
    limits: tuple[LimitParam, ...]      # () : not read, ``limits_unread`` says why
    top_speed: TopSpeedParams | None
    limits_unread: str
    estimator_messages: tuple[str, ...]  # asked for with MAV_CMD_REQUEST_MESSAGE, first wins
    prearm_command: bool                 # MAV_CMD_RUN_PREARM_CHECKS makes it say what fails


# --------------------------------------------------------------------------- identification

@dataclass(frozen=True)
class IdentFacts:
    """What identification reads and assumes, and the manoeuvre it flies."""

    params: tuple[str, ...]                         # read with PARAM_REQUEST_READ (or a .tlog)
    priors: Callable[[Mapping[str, float]], Priors]  # {name: value} (any subset) -> priors
    headroom: float                                 # setpoints up to this x the limits
    params_label: str                               # for the log line naming what was read
    # per channel ("speed", "turn rate"): the parameters to check when the model does not
    # explain a manoeuvre (companion calibrate's one line)
    model_hints: Mapping[str, str] = field(default_factory=dict)
    # (speed m/s, turn rate rad/s): the RMS up to which the model is taken to explain a flight
    # (companion calibrate stops above it; issue 11's held-out standard on ArduPilot)
    explain_limit: tuple[float, float] = (0.15, 0.15)
    # the excitation manoeuvre this autopilot flies whatever steers the rover (a name of
    # companion.ident.excite.manoeuvres: PX4's "velocity vectors"); None: the steering kind's
    manoeuvre: str | None = None


# --------------------------------------------------------------------------- the plant

@dataclass(frozen=True)
class PlantFacts:
    """What ``sitl_plant`` emulates of this autopilot besides the profile's own facts."""

    modes: tuple[str, ...]             # the modes it has (names of the mode table)
    unsettable: tuple[str, ...]        # reported, never entered on request
    initial_mode: str
    mode_refused: int                  # MAV_RESULT of a refused mode change
    arm_texts: tuple[str, str]         # STATUSTEXT when armed, disarmed
    tick_aligned: bool                 # telemetry on the scheduler's ticks (a real vehicle's)
    # (name, value, MAV_PARAM_TYPE) served, from the rover, loop rate, sysid, offboard timeout
    params: Callable[..., list[tuple[str, float, int]]]
    # its battery failsafe (low, its action HOLD) as its own text says it (None: not modelled)
    battery_text: str | None = None


# --------------------------------------------------------------------------- failsafes, estimate

MAV_STATE_CRITICAL, MAV_STATE_EMERGENCY = 5, 6


@dataclass(frozen=True)
class FailsafeFacts:
    """How the autopilot's own failsafes show on the link.

    ``texts``: (lower-case piece of a STATUSTEXT, cause) pairs, first match wins; a cause is one
    of ``ekf``, ``gcs``, ``battery``, ``fence``, ``radio``, ``crash``, ``guided_timeout``,
    ``failsafe`` (unnamed). ``cleared``: pieces of the texts that say a failsafe has ended (they
    are tested first, so "EKF failsafe cleared" never reads as a new one). ``states``: the
    HEARTBEAT ``system_status`` values the autopilot reports while a failsafe holds the vehicle.
    ``link_causes``: the autopilot's answers to the companion's own silence (ArduPilot's
    guided timeout, PX4's offboard loss): once the link is back the companion takes the
    vehicle back, as from its own HOLD. ``leaves_on_silence``: that answer leaves the track
    mode (PX4), so a mode change while the companion's link is stalled is that answer unless a
    text names another failsafe. ``sensors``: (SYS_STATUS health bit, cause) pairs: a bit the
    autopilot reports enabled turning unhealthy names that failsafe as a text would (a battery
    monitor clears MAV_SYS_STATUS_SENSOR_BATTERY when its failsafe triggers)."""

    texts: tuple[tuple[str, str], ...]
    cleared: tuple[str, ...]
    states: frozenset[int] = frozenset({MAV_STATE_CRITICAL, MAV_STATE_EMERGENCY})
    link_causes: frozenset[str] = frozenset()
    leaves_on_silence: bool = False
    sensors: tuple[tuple[int, str], ...] = ((MAV_SYS_STATUS_SENSOR_BATTERY, "battery"),)


@dataclass(frozen=True)
class EstimateFacts:
    """How the estimator says its position estimate is usable: one message (asked for at
    ``rate_hz``), its ``flags`` field, the bits that must all be set (``need``) and the bits
    none of which may be (``bad``), each with the words the companion says; ``variances``: the
    message's fields of normalised test ratios (1.0 = the estimator's own rejection gate) that
    the companion compares with its limit. ``once_shown``: the bits of ``need`` that count only
    after the estimator has set them once (absolute position: a vehicle without GPS, whose EKF
    never had an origin, still flies a local mission; one that loses GPS pauses)."""

    message: str
    message_id: int
    flags_field: str
    need: tuple[tuple[int, str], ...]
    bad: tuple[tuple[int, str], ...]
    variances: tuple[str, ...]
    rate_hz: float = 5.0
    once_shown: int = 0


# --------------------------------------------------------------------------- the profile

@dataclass(frozen=True)
class AutopilotProfile:
    name: str                                      # "ardupilot": flags, logs, JSON
    label: str                                     # "ArduPilot": for people
    mav_autopilot: tuple[int, ...]                 # HEARTBEAT.autopilot; the first is sent
    modes: ModeTable
    mode_types: frozenset[int] | None              # MAV_TYPEs the table is for (None: all)
    track_mode: str                                # follows the companion's setpoints
    hold_mode: str                                 # stands still; the companion hands back in it
    # MAV_CMD_DO_SET_MODE's (param1, param2, param3) for a mode, and back (param2, param3 ->
    # custom_mode, None for a mode that cannot be asked so)
    set_mode_params: Callable[[Mode], tuple[float, float, float]]
    requested_mode: Callable[[float, float], int | None]
    # the heartbeat's mode name (as pymavlink's mode_string_v10 gives it)
    mode_name: Callable[[ModeTable, int, int], str]
    setpoint: SetpointEncoding
    offboard_warmup: float | None                  # vehicle s of setpoints before the track
    # mode is asked for: the vehicle refuses it without a stream and leaves it when the stream
    # stops (PX4's offboard); None: targets are taken in the mode and time out (ArduPilot GUIDED)
    bytewise_params: bool                          # integers' bytes in PARAM_VALUE's float
    preflight: PreflightFacts
    ident: IdentFacts
    plant: PlantFacts
    failsafe: FailsafeFacts
    estimate: EstimateFacts
    # the stored mission's item 0 is the home position, not a mission item (ArduPilot; PX4
    # keeps home apart): companion.mav.mission_transfer
    mission_home_item: bool = False
    # the guided sub-mode inside the mission (ArduPilot Rover's MAV_CMD_NAV_GUIDED_ENABLE):
    # companion run --handover; None: the autopilot has none
    auto_mode: str | None = None
    # Bundled vehicle files (companion/sim/vehicles/) identified on this autopilot -> the
    # steering kind of the vehicle each was identified on. ``run`` without a vehicle file flies
    # one whose recorded parameters (its ``[source]`` values of ``ident.params``) and steering
    # kind the vehicle has (companion.live.presets); () : none.
    presets: Mapping[str, str] = field(default_factory=dict)
    # The robust tuner's settings (companion.sim.robust.config.RobustConfig fields; ``spread`` as a
    # mapping of Spread's) for a vehicle flown by these setpoints: what the identified model
    # leaves out of how this autopilot drives (companion.profiles.tune_settings).
    tune: Mapping[str, Any] = field(default_factory=dict)
    # RoverParams fields of the inner loops only this autopilot has (PX4's course loop,
    # ``course_gain``): a vehicle model with one set was identified on it
    # (companion.profiles.autopilot_of_model, the vehicle file's [course])
    model_fields: tuple[str, ...] = ()
    # modes the autopilot reports while it starts and leaves on its own (ArduPilot's
    # INITIALISING, then its INITIAL_MODE): nobody's choice (companion.live.runner)
    boot_modes: frozenset[str] = frozenset()
    # what a drop in the receiver's class (GPS_RAW_INT) does: companion.profiles.gnss
    gnss: GnssPolicy = GnssPolicy()

    def modes_for(self, mav_type: int) -> ModeTable:
        """The mode table for a vehicle of this MAV_TYPE (empty for a type it does not cover)."""
        if self.mode_types is None or mav_type in self.mode_types:
            return self.modes
        return ModeTable()

    def priors_from(self, values: Mapping[str, float]) -> Priors:
        """The identification priors from the parameters read (only this profile's count)."""
        return self.ident.priors({k: v for k, v in values.items() if k in self.ident.params})

    def settled(self, mode: str | None) -> bool:
        """A mode someone chose: one of the table's, not one the autopilot starts in (a name
        outside the table, e.g. a heartbeat without a custom mode, is not yet a choice)."""
        return mode in self.modes.names() and mode not in self.boot_modes

    def mode_number(self, name: str) -> int:
        """``custom_mode`` of a mode of the table (KeyError for another name)."""
        mode = self.modes.by_name(name)
        if mode is None:
            raise KeyError(f"{self.label} has no mode {name!r}")
        return mode.custom_mode
