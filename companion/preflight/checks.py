"""The preflight checks: pure functions from what the vehicle said to ok / warn / fail.

Each check reads an :class:`Observed` (the heartbeat, the parameters, a few status messages, what
the stream-rate request did, the companion's own settings) and returns :class:`Check` rows: the
parameter or message looked at, its value, what to set and why. A row may carry ``fix``, the
parameter values ``companion preflight --fix`` would set; only what has one right answer for
every rover gets one (failsafe settings), never a vehicle's own limits.

What differs between autopilots is their profile's (:mod:`companion.profiles`, found by
``Observed.autopilot``): the parameter names and the values wanted
(:class:`~companion.profiles.autopilot.PreflightFacts`: how the frame shows the steering kind,
the failsafe, the rate cap, the inner-loop limits), the track mode; what a steering kind is, its
verdict and why, is its steering profile's. Facts behind the rules (``vehicle-interfaces.md``;
ArduPilot Rover, PX4 sources):

* HEARTBEAT type 10 is a ground rover, 11 a boat (ArduPilot Rover sends 11 with FRAME_CLASS 2);
* skid steering is SERVOn_FUNCTION 73 (throttle left) and 74 (throttle right); Ackermann is 26
  (ground steering) with 70 (throttle); PX4: CA_AIRFRAME 6 differential, 5 Ackermann, 13 mecanum;
* SYS_STATUS's MAV_SYS_STATUS_PREARM_CHECK bit is healthy when the pre-arm checks pass;
* EKF_STATUS_REPORT / ESTIMATOR_STATUS flags: 1 attitude, 2 horizontal velocity, 8 relative and
  16 absolute horizontal position, 1024 uninitialised, 32768 GPS glitching; ArduPilot's EKF
  failsafe trips at FS_EKF_THRESH (0.8) on the variances, ground stations go red there;
* the GCS failsafe watches heartbeats of MAV_GCS_SYSID (SYSID_MYGCS before 2025; a range up to
  MAV_GCS_SYSID_HI); MAV_OPTIONS bit 0 (SYSID_ENFORCE before) drops every other system's
  messages, the companion's setpoints included; PX4's offboard-loss failsafe watches the
  setpoint stream itself (COM_OF_LOSS_T, then COM_OBL_RC_ACT);
* a message rate above 0.8 x SCHED_LOOP_RATE is refused.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from .. import profiles
from ..profiles.autopilot import (
    AirframeFrame,
    AutopilotProfile,
    GcsFailsafe,
    OffboardFailsafe,
    ServoFrame,
    TopSpeedParams,
)

OK, WARN, FAIL = "ok", "warn", "fail"
MAV_TYPE_GROUND_ROVER, MAV_TYPE_SURFACE_BOAT = 10, 11
PREARM_BIT = 0x10000000                     # MAV_SYS_STATUS_PREARM_CHECK
EKF_ATTITUDE, EKF_VEL_HORIZ, EKF_POS_REL, EKF_POS_ABS = 1, 2, 8, 16
EKF_UNINITIALIZED, EKF_GPS_GLITCHING = 1024, 32768
EKF_WARN, EKF_FAIL = 0.5, 0.8               # variance ratios (FS_EKF_THRESH's default is 0.8)
RATE_CAP = 0.8                              # streams up to 0.8 x SCHED_LOOP_RATE
LIMIT_TOLERANCE = 0.25                      # vehicle file vs autopilot, relative
# MAV_SYS_STATUS_SENSOR bits worth naming when unhealthy
SENSOR_NAMES = {0x1: "gyro", 0x2: "accelerometer", 0x4: "compass", 0x8: "barometer",
                0x20: "GPS", 0x8000: "motor outputs", 0x200000: "AHRS",
                0x1000000: "logging", 0x2000000: "battery", PREARM_BIT: "pre-arm checks"}


@dataclass(frozen=True)
class Check:
    name: str            # the parameter or message looked at
    status: str          # OK, WARN or FAIL
    value: str           # what the vehicle has
    want: str            # what to set
    why: str
    fix: Mapping[str, float] = field(default_factory=dict)   # --fix: parameter -> value

    def as_dict(self) -> dict[str, str]:
        return {"name": self.name, "status": self.status, "value": self.value,
                "want": self.want, "why": self.why}


@dataclass(frozen=True)
class Ekf:
    flags: int
    velocity_variance: float = 0.0
    pos_horiz_variance: float = 0.0
    pos_vert_variance: float = 0.0
    compass_variance: float = 0.0


@dataclass(frozen=True)
class Streams:
    """What SET_MESSAGE_INTERVAL for the pose messages did, and what then arrived."""
    asked_hz: float
    results: Mapping[str, int | None]          # message -> COMMAND_ACK result (None: no ACK)
    measured_hz: Mapping[str, float | None]    # message -> rate on the vehicle's clock


@dataclass(frozen=True)
class Limits:
    """The vehicle model's limits (a vehicle file), to hold against the autopilot's."""
    max_speed: float            # m/s
    max_accel: float            # m/s^2
    max_decel: float            # m/s^2
    max_yaw_rate: float         # rad/s
    max_yaw_accel: float        # rad/s^2
    source: str = "the vehicle file"


@dataclass(frozen=True)
class Observed:
    autopilot: str                          # a profile's name (companion.profiles.AUTOPILOTS)
    mav_type: int
    modes: frozenset[str]                   # the mode names the vehicle type has
    armed: bool = False
    mavlink_version: int = 2                # of the vehicle's frames
    signed: bool = False                    # the vehicle's frames carry a signature
    signing_key: bool = False               # the companion signs (and verified the vehicle's)
    serial: bool = False                    # the link is a serial device (a wire)
    companion_sysid: int = 255
    vehicle_sysid: int | None = None        # the vehicle's (the companion's too, by default)
    params: Mapping[str, float] = field(default_factory=dict)
    sensors: tuple[int, int, int] | None = None      # SYS_STATUS present, enabled, health
    prearm_texts: tuple[str, ...] = ()
    ekf: Ekf | None = None
    origin: tuple[float, float] | None = None        # GPS_GLOBAL_ORIGIN lat, lon (deg)
    streams: Streams | None = None
    limits: Limits | None = None

    @property
    def profile(self) -> AutopilotProfile:
        return profiles.autopilot_named(self.autopilot)


def _num(value: float) -> str:
    return f"{value:g}"


def _param(name: str, obs: Observed, want: str, why: str) -> Check | None:
    """A 'could not read' row for a parameter the vehicle did not report, else None."""
    if name in obs.params and math.isfinite(obs.params[name]):
        return None
    return Check(name, WARN, "not reported", want,
                 f"the vehicle did not report {name} (another firmware version?): {why}")


# --------------------------------------------------------------------------- the vehicle

def check_vehicle(obs: Observed) -> list[Check]:
    kind = {MAV_TYPE_GROUND_ROVER: "rover", MAV_TYPE_SURFACE_BOAT: "boat"}.get(obs.mav_type)
    value = f"{kind or 'not a rover'} (MAV_TYPE {obs.mav_type}, {obs.autopilot})"
    if kind is None:
        return [Check("HEARTBEAT type", FAIL, value, "a rover (10) or boat (11)",
                      "the companion drives ground rovers and boats by speed and turn rate; "
                      "this autopilot is another kind of vehicle")]
    return [Check("HEARTBEAT type", OK, value, "a rover (10) or boat (11)",
                  "a vehicle the companion drives by speed and turn rate")]


def _servo_functions(params: Mapping[str, float]) -> dict[int, list[str]]:
    out: dict[int, list[str]] = {}
    for name, value in params.items():
        if name.startswith("SERVO") and name.endswith("_FUNCTION") and math.isfinite(value):
            out.setdefault(int(value), []).append(name)
    return out


def check_steering(obs: Observed) -> list[Check]:
    """Skid-steer or Ackermann (a steering profile), from the frame and the servo functions or
    the airframe, as the autopilot's profile says it shows (the paper's model is a
    differential-drive rover)."""
    frame = obs.profile.preflight.frame
    if isinstance(frame, AirframeFrame):
        return _steering_by_airframe(obs, frame)
    return _steering_by_servos(obs, frame)


def _steering_by_airframe(obs: Observed, frame: AirframeFrame) -> list[Check]:
    model, name = profiles.model_steering(), frame.param
    want = f"{model.airframe} ({model.airframe_label})"
    missing = _param(name, obs, want, "the frame tells skid steering from Ackermann")
    if missing:
        return [missing]
    airframe = int(obs.params[name])
    kind = profiles.steering_by_airframe(airframe)
    label = (f"{kind.label} ({kind.airframe_label})" if kind is not None
             else frame.other_rovers.get(airframe, "not a rover"))
    value = f"{label} ({name} {airframe})"
    if kind is model:
        return [Check(name, OK, value, f"{model.airframe}", model.why)]
    if kind is not None:
        return [Check(name, kind.verdict, value, want, kind.why)]
    if airframe in frame.other_rovers:
        return [Check(name, WARN, value, want, "the companion's model is a differential-drive "
                      "rover")]
    return [Check(name, FAIL, value, want, "the airframe is not a rover")]


def _steering_by_servos(obs: Observed, frame: ServoFrame) -> list[Check]:
    p = obs.params
    classes = " or ".join(f"{k} ({v})" for k, v in frame.classes.items())
    missing = _param(frame.class_param, obs, classes, "the frame tells a rover from a balance bot")
    if missing:
        return [missing]
    frame_class = int(p[frame.class_param])
    servos = _servo_functions(p)
    kind = profiles.steering_by_servos(set(servos))
    model = profiles.model_steering()
    outputs = ", ".join(f"{n} {f}" for s in profiles.STEERING.values()
                        for f in s.servo_functions for n in servos.get(f, []))
    name = f"{frame.class_param}, SERVOn_FUNCTION"
    if frame_class not in frame.classes:
        return [Check(name, FAIL, f"{frame.class_param} {frame_class}", classes,
                      "not a rover or boat frame (3 is a balance bot): the companion's model "
                      "does not describe it")]
    frame_type = int(p.get(frame.type_param, 0) or 0)
    if frame_type != 0:
        return [Check(name, WARN, f"{frame.type_param} {frame_type} (omni)",
                      f"{frame.type_param} 0",
                      "an omni frame moves sideways too; the companion commands only speed "
                      "and turn rate")]
    if kind is model:
        return [Check(name, OK, f"{kind.label} ({outputs})", kind.servo_text, kind.why)]
    if kind is not None:
        model_servos = " / ".join(map(str, model.servo_functions))
        return [Check(name, kind.verdict, f"{kind.label} ({outputs})",
                      f"{model.name} steering ({model_servos})", kind.why)]
    either = " or ".join(f"{' and '.join(map(str, s.servo_functions))} ({s.label})"
                         for s in profiles.STEERING.values())
    return [Check(name, FAIL, "no throttle outputs" + (f" ({outputs})" if outputs else ""),
                  f"SERVOn_FUNCTION {either}",
                  "no motor output is assigned to throttle: the rover cannot move")]


# --------------------------------------------------------------------------- the link

def check_protocol(obs: Observed) -> list[Check]:
    value = f"MAVLink {obs.mavlink_version}"
    if obs.mavlink_version >= 2:
        return [Check("MAVLink", OK, value, "MAVLink 2", "signing and every message the "
                      "companion uses need MAVLink 2")]
    return [Check("MAVLink", WARN, value, "MAVLink 2 (SERIALn_PROTOCOL 2 on the companion's "
                  "port)", "MAVLink 1 cannot be signed and drops message extensions")]


def check_streams(obs: Observed) -> list[Check]:
    s = obs.streams
    name = "LOCAL_POSITION_NED, ATTITUDE rate"
    if s is None:
        return [Check(name, WARN, "not measured", "pose telemetry at the loop's rate",
                      "the stream rates were not checked")]
    asked = s.asked_hz
    measured = {k: v for k, v in s.measured_hz.items()}
    shown = ", ".join(f"{k} {'none' if v is None else f'{v:.1f} Hz'}" for k, v in measured.items())
    value = f"{shown} (asked {asked:g} Hz)"
    want = f"{asked:g} Hz"
    if any(v is None for v in measured.values()):
        return [Check(name, FAIL, value, want, "pose telemetry does not arrive: the control "
                      "loop has nothing to run on")]
    refused = [k for k, r in s.results.items() if r not in (0, None)]
    loop_param = obs.profile.preflight.loop_rate_param
    loop = obs.params.get(loop_param) if loop_param else None
    if refused:
        need = math.ceil(asked / RATE_CAP)
        fix: dict[str, float] = {}
        extra = ""
        if loop_param and loop is not None and loop < need:
            fix = {loop_param: float(need)}
            extra = (f"; {loop_param} {loop:g} allows {RATE_CAP * loop:g} Hz, {need} allows "
                     f"{asked:g} Hz (after a reboot)")
        return [Check(name, WARN, value + f", refused for {', '.join(refused)}",
                      f"{want}" + (f" ({loop_param} {need})" if fix else ""),
                      "the vehicle refused the rate; the companion falls back to a slower one"
                      + extra, fix)]
    slow = [k for k, v in measured.items() if v is not None and v < 0.8 * asked]   # (none is)
    if slow:
        return [Check(name, WARN, value, want, "accepted but slower on the wire: a slow serial "
                      "link (baud rate) or a busy autopilot; the loop runs at what arrives")]
    return [Check(name, OK, value, want, "the control loop's rate arrives")]


def check_signing(obs: Observed) -> list[Check]:
    want = "MAVLink 2 signing (--signing-key; the vehicle's key set by SETUP_SIGNING)"
    if obs.signing_key:
        return [Check("signing", OK, "signed, the vehicle's signature verified", want,
                      "only holders of the key can command the rover")]
    if obs.signed:
        return [Check("signing", WARN, "the vehicle signs; the companion has no key", want,
                      "give the companion the key (--signing-key): its unsigned setpoints may "
                      "be refused on a signed link")]
    if obs.serial:
        return [Check("signing", OK, "unsigned, on a serial wire", want,
                      "a wire between the boards; sign radio and network links")]
    return [Check("signing", WARN, "unsigned", want,
                  "anyone who can reach this link can command the rover")]


# --------------------------------------------------------------------------- the estimate

def check_origin(obs: Observed) -> list[Check]:
    want = "an EKF origin (GPS lock, or SET_GPS_GLOBAL_ORIGIN)"
    if obs.origin is None:
        return [Check("GPS_GLOBAL_ORIGIN", FAIL, "not set", want,
                      "without an origin ArduPilot ignores GUIDED setpoints, and missions "
                      "placed by latitude / longitude cannot be anchored")]
    lat, lon = obs.origin
    return [Check("GPS_GLOBAL_ORIGIN", OK, f"{lat:.7f}, {lon:.7f}", want,
                  "local positions and geodetic missions share this origin")]


def check_ekf(obs: Observed) -> list[Check]:
    name = "EKF_STATUS_REPORT"
    want = "attitude, velocity and horizontal position good, variances < 0.5"
    e = obs.ekf
    if e is None:
        return [Check(name, WARN, "no answer", want,
                      "the position estimate's health could not be read")]
    missing = [label for bit, label in ((EKF_ATTITUDE, "attitude"),
                                        (EKF_VEL_HORIZ, "horizontal velocity"),
                                        (EKF_POS_REL, "relative position")) if not e.flags & bit]
    variances = {"velocity": e.velocity_variance, "position": e.pos_horiz_variance,
                 "compass": e.compass_variance}
    worst = max(variances, key=lambda k: variances[k])
    value = f"flags 0x{e.flags:x}, {worst} variance {variances[worst]:.2f}"
    if e.flags & EKF_UNINITIALIZED or e.flags & EKF_GPS_GLITCHING or missing:
        bad = missing + (["uninitialised"] if e.flags & EKF_UNINITIALIZED else []) \
            + (["GPS glitching"] if e.flags & EKF_GPS_GLITCHING else [])
        return [Check(name, FAIL, value + " (" + ", ".join(bad) + ")", want,
                      "LOCAL_POSITION_NED is not trustworthy: the tracker would steer on a "
                      "wrong pose")]
    if variances[worst] >= EKF_FAIL:
        return [Check(name, FAIL, value, want, "the EKF failsafe trips at 0.8 (FS_EKF_THRESH)")]
    if variances[worst] >= EKF_WARN:
        return [Check(name, WARN, value, want, "the estimate is uncertain (ground stations "
                      "turn amber at 0.5)")]
    if not e.flags & EKF_POS_ABS:
        return [Check(name, WARN, value + " (no absolute position)", want,
                      "a relative estimate only: missions placed by latitude / longitude "
                      "cannot be flown")]
    return [Check(name, OK, value, want, "the pose the tracker steers on is sound")]


# --------------------------------------------------------------------------- arming, modes

def check_prearm(obs: Observed) -> list[Check]:
    name = "SYS_STATUS pre-arm"
    want = "pre-arm checks passing"
    if obs.armed:
        return [Check(name, OK, "armed", want, "the vehicle is armed already")]
    if obs.sensors is None:
        return [Check(name, WARN, "no SYS_STATUS", want, "the pre-arm state could not be read")]
    present, enabled, health = obs.sensors
    texts = "; ".join(dict.fromkeys(obs.prearm_texts))
    unhealthy = [label for bit, label in SENSOR_NAMES.items()
                 if bit != PREARM_BIT and present & bit and enabled & bit and not health & bit]
    if present & PREARM_BIT:
        if health & PREARM_BIT:
            return [Check(name, OK, "pre-arm checks pass", want, "the vehicle can arm")]
        value = "failing" + (f": {texts}" if texts else "") + \
            (f" (unhealthy: {', '.join(unhealthy)})" if unhealthy else "")
        return [Check(name, FAIL, value, want,
                      "the vehicle refuses to arm until these pass (SITL: about 40 s after "
                      "boot, once the EKF runs)")]
    if unhealthy:
        return [Check(name, FAIL, f"unhealthy: {', '.join(unhealthy)}", want,
                      "an enabled sensor reports a fault")]
    return [Check(name, OK, "sensors healthy (no pre-arm bit reported)", want,
                  "no fault reported")]


def check_track_mode(obs: Observed) -> list[Check]:
    mode = obs.profile.track_mode
    if mode in obs.modes:
        return [Check(mode, OK, "available", f"{mode} available",
                      "the mode in which the vehicle follows the companion's setpoints")]
    return [Check(mode, FAIL, "not among the vehicle's modes", f"{mode} available",
                  "the vehicle has no mode that follows external setpoints")]


# --------------------------------------------------------------------------- failsafes

def check_failsafes(obs: Observed) -> list[Check]:
    """The autopilot's failsafe for a companion that falls silent, as its profile names it."""
    facts = obs.profile.preflight.failsafe
    if isinstance(facts, OffboardFailsafe):
        return _offboard_failsafe(obs, facts)
    return _gcs_failsafe(obs, facts)


def _gcs_sysid_names(f: GcsFailsafe, params: Mapping[str, float]) -> tuple[str, str, str]:
    """(GCS system id parameter, its upper bound or '', enforce parameter) of this firmware:
    the first spelling it has, else the oldest."""
    return next((names for names in f.sysid_params if names[0] in params), f.sysid_params[-1])


def _failsafe_action(obs: Observed, f: GcsFailsafe) -> Check:
    """The GCS failsafe's action: set, and not "nothing" (both identities' checks)."""
    p = obs.params
    missing = _param(f.action, obs, f.action_hold_label, "what the failsafe does")
    if missing:
        return missing
    if p[f.action] == 0:
        return Check(f.action, WARN, "0 (nothing)", f.action_hold_label,
                     "a failsafe that does nothing leaves the rover driving",
                     {f.action: float(f.action_hold)})
    return Check(f.action, OK, _num(p[f.action]), f.action_hold_label,
                 f"the failsafe takes the rover out of {obs.profile.track_mode}")


def _gcs_failsafe(obs: Observed, f: GcsFailsafe) -> list[Check]:
    if obs.vehicle_sysid is not None and obs.companion_sysid == obs.vehicle_sysid:
        return _gcs_failsafe_onboard(obs, f)
    p, out = obs.params, []
    me = obs.companion_sysid
    missing = _param(f.enable, obs, "1", "the GCS failsafe notices a dead companion")
    if missing:
        out.append(missing)
    elif p[f.enable] == 0:
        out.append(Check(f.enable, WARN, "0 (off)", "1",
                         f"the companion's heartbeat (system {me}) is a GCS heartbeat: with "
                         f"the failsafe on, a companion that dies is noticed within "
                         f"{f.timeout} and {f.action} runs; off, {f.silent_companion}",
                         {f.enable: 1.0}))
    else:
        out.append(Check(f.enable, OK, _num(p[f.enable]), "1",
                         f"a companion (or ground station) that falls silent triggers {f.action}"))
    out.append(_failsafe_action(obs, f))
    lo_t, hi_t = f.timeout_range
    missing = _param(f.timeout, obs, f"{f.timeout_fix:g} s",
                     "how long a silent companion goes unnoticed")
    if missing:
        out.append(missing)
    else:
        t = p[f.timeout]
        if lo_t <= t <= hi_t:
            out.append(Check(f.timeout, OK, f"{t:g} s", f"{lo_t:g} to {hi_t:g} s",
                             "longer than a few lost 1 Hz heartbeats, short enough to matter"))
        else:
            out.append(Check(f.timeout, WARN, f"{t:g} s", f"{lo_t:g} to {hi_t:g} s "
                             f"({f.timeout_fix:g})",
                             f"the companion sends a heartbeat each second: under {lo_t:g} s a "
                             f"few lost ones trip it, over {hi_t:g} s a dead companion goes "
                             "unnoticed", {f.timeout: f.timeout_fix}))
    sysid_name, hi_name, enforce_name = _gcs_sysid_names(f, p)
    missing = _param(sysid_name, obs, f"{me}", "which system the GCS failsafe watches")
    if missing:
        out.append(missing)
        return out
    lo = int(p[sysid_name])
    hi = int(p.get(hi_name, 0) or 0) if hi_name else 0
    watched = range(lo, max(lo, hi) + 1)
    enforce = (int(p.get(enforce_name, 0) or 0) & 1) if enforce_name else 0
    value = f"{lo}" + (f"..{hi}" if hi > lo else "") + (f", {enforce_name} enforcing"
                                                          if enforce else "")
    if me in watched:
        out.append(Check(sysid_name, OK, value, f"{me} (the companion's system id)",
                         "the GCS failsafe and the vehicle listen to the companion"))
    elif enforce:
        out.append(Check(sysid_name, FAIL, value, f"{me} (the companion's system id)",
                         f"{enforce_name} makes the vehicle drop every message from another "
                         "system: the companion's setpoints are ignored",
                         {sysid_name: float(me)}))
    else:
        out.append(Check(sysid_name, WARN, value, f"{me} (the companion's system id)",
                         "the GCS failsafe watches another system: a dead companion goes "
                         "unnoticed", {sysid_name: float(me)}))
    return out


def _gcs_failsafe_onboard(obs: Observed, f: GcsFailsafe) -> list[Check]:
    """The companion is a component of the vehicle's own system (the default, docs/
    ground-station.md): the GCS failsafe watches the ground station alone, and the companion's
    own death is caught by the guided timeout, not by this failsafe."""
    p, out = obs.params, []
    me = obs.companion_sysid
    missing = _param(f.enable, obs, "1", "the GCS failsafe notices a lost ground station")
    if missing:
        out.append(missing)
    elif p[f.enable] == 0:
        out.append(Check(f.enable, WARN, "0 (off)", "1",
                         "the ground station's link can be lost unnoticed; the companion "
                         f"(system {me}, the vehicle's own) does not stand in for it",
                         {f.enable: 1.0}))
    else:
        out.append(Check(f.enable, OK, _num(p[f.enable]), "1",
                         f"a lost ground station triggers {f.action}; the companion's heartbeat "
                         "does not keep it from firing"))
    out.append(_failsafe_action(obs, f))
    lo_t, hi_t = f.timeout_range
    missing = _param(f.timeout, obs, f"{f.timeout_fix:g} s",
                     "how long a lost ground station goes unnoticed")
    if missing:
        out.append(missing)
    elif lo_t <= p[f.timeout] <= hi_t:
        out.append(Check(f.timeout, OK, f"{p[f.timeout]:g} s", f"{lo_t:g} to {hi_t:g} s",
                         "longer than a few lost 1 Hz heartbeats, short enough to matter"))
    else:
        out.append(Check(f.timeout, WARN, f"{p[f.timeout]:g} s",
                         f"{lo_t:g} to {hi_t:g} s ({f.timeout_fix:g})",
                         f"a ground station heart-beats each second: under {lo_t:g} s a few "
                         f"lost ones trip it, over {hi_t:g} s a lost one goes unnoticed",
                         {f.timeout: f.timeout_fix}))
    sysid_name, hi_name, _enforce_name = _gcs_sysid_names(f, p)
    missing = _param(sysid_name, obs, "the ground station's id (255)",
                     "which system the GCS failsafe watches")
    if missing:
        out.append(missing)
        return out
    lo = int(p[sysid_name])
    hi = int(p.get(hi_name, 0) or 0) if hi_name else 0
    value = f"{lo}" + (f"..{hi}" if hi > lo else "")
    if lo <= me <= max(lo, hi):
        out.append(Check(sysid_name, WARN, value, "the ground station's id (255), not "
                         f"{me}", f"the GCS failsafe watches system {me}, the vehicle and its "
                         "companion: a lost ground station goes unnoticed", {sysid_name: 255.0}))
    else:
        out.append(Check(sysid_name, OK, value, "the ground station's id",
                         f"the companion (system {me}, component 191) is not taken for the "
                         "ground station"))
    return out


def _offboard_failsafe(obs: Observed, f: OffboardFailsafe) -> list[Check]:
    p, out = obs.params, []
    who = obs.profile.label
    t_max = f.loss_timeout_max
    missing = _param(f.loss_timeout, obs, f"{t_max:g} s or less",
                     f"how long {who} follows a lost stream")
    if missing:
        out.append(missing)
    else:
        t = p[f.loss_timeout]
        ok = 0.0 < t <= t_max
        out.append(Check(f.loss_timeout, OK if ok else WARN, f"{t:g} s", f"0 < t <= {t_max:g} s",
                         f"{who} holds the last setpoint this long after the companion falls "
                         "silent" + ("" if ok else ": the rover drives blind meanwhile"),
                         {} if ok else {f.loss_timeout: t_max}))
    hold = f"{f.action_hold} ({f.action_names[f.action_hold]})"
    missing = _param(f.action, obs, hold, f"what {who} does when offboard is lost")
    if missing:
        out.append(missing)
    else:
        act = int(p[f.action])
        value = f"{act} ({f.action_names.get(act, '?')})"
        if act == f.action_hold:
            out.append(Check(f.action, OK, value, hold,
                             "a lost companion leaves the rover stopped"))
        else:
            out.append(Check(f.action, WARN, value, hold,
                             "on offboard loss the rover should stop where it is, not wait for "
                             "a pilot's sticks or drive away", {f.action: float(f.action_hold)}))
    return out


# --------------------------------------------------------------------------- inner loops

def _compare(name: str, autopilot_si: float, model_si: float, unit_scale: float, unit: str,
             value: str, limits: Limits) -> Check | None:
    if not (math.isfinite(model_si) and math.isfinite(autopilot_si)) or autopilot_si <= 0:
        return None
    if abs(model_si - autopilot_si) <= LIMIT_TOLERANCE * autopilot_si:
        return None
    return Check(name, WARN, value, f"{model_si / unit_scale:.3g} {unit} as {limits.source} "
                 "says, or re-identify", f"{limits.source} models {model_si / unit_scale:.3g} "
                 f"{unit}: gains tuned on it expect another vehicle (companion calibrate)")


def check_limits(obs: Observed) -> list[Check]:
    """The inner-loop limits the vehicle model starts from (the profile's priors,
    companion.profiles), where the autopilot's profile names them."""
    facts = obs.profile.preflight
    if not facts.limits:
        return [Check("inner-loop limits", WARN, "not read", "the rover's speed and turn-rate "
                      "limits", facts.limits_unread)]
    p, out, lim = obs.params, [], obs.limits
    for param in facts.limits:
        name, unit, scale, what = param.name, param.unit, param.to_si, param.what
        want = (f">= 0 {unit} (0: as {param.zero_as})" if param.zero_as else f"> 0 {unit}")
        missing = _param(name, obs, want, f"{what} of the vehicle model")
        if missing:
            out.append(missing)
            continue
        v = p[name]
        value = f"{v:g} {unit}"
        if v < 0 or (v == 0 and not param.zero_as):
            out.append(Check(name, WARN, value + (" (no limit)" if v == 0 else ""),
                             want, f"{what}: without it the vehicle answers a step "
                             "at once and the model's rate limit is a guess"))
            continue
        if lim is not None:
            model = getattr(lim, param.field)
            # 0: as another parameter (unknown when not reported: nothing to compare)
            ap = (p.get(param.zero_as, math.nan) if v == 0 and param.zero_as else v) * scale
            row = _compare(name, ap, model, scale, unit, value, lim)
            if row is not None:
                out.append(row)
                continue
        out.append(Check(name, OK, value, want, f"{what}: the vehicle model starts from it"))
    if facts.top_speed is not None:
        out.append(_top_speed(obs, facts.top_speed))
    return out


def _top_speed(obs: Observed, f: TopSpeedParams) -> Check:
    p = obs.params
    name = f"{f.wp_speed}, {f.cruise_speed} / {f.cruise_throttle}"
    missing = _param(f.cruise_speed, obs, "> 0 m/s", f"the speed at {f.cruise_throttle}")
    if missing:
        return missing
    cruise, throttle = p[f.cruise_speed], p.get(f.cruise_throttle, 0.0)
    wp = p.get(f.wp_speed, 0.0)
    if not (cruise > 0 and 0 < throttle <= 100):
        return Check(name, WARN, f"{f.cruise_speed} {cruise:g}, {f.cruise_throttle} {throttle:g}",
                     f"{f.cruise_speed} > 0 at {f.cruise_throttle} 1..100 %",
                     "the throttle feed-forward and the model's top speed come from these")
    full = cruise * 100.0 / throttle
    top = wp if 0 < wp <= full else full
    value = f"top speed {top:.3g} m/s ({f.wp_speed} {wp:g}, full throttle {full:.3g})"
    if obs.limits is not None:
        row = _compare(name, top, obs.limits.max_speed, 1.0, "m/s", value, obs.limits)
        if row is not None:
            return row
    return Check(name, OK, value, "> 0", f"{obs.profile.track_mode} holds speed setpoints to this")


# --------------------------------------------------------------------------- all of them

def run_checks(obs: Observed) -> list[Check]:
    rows = (check_vehicle(obs) + check_steering(obs) + check_protocol(obs)
            + check_streams(obs) + check_origin(obs) + check_ekf(obs) + check_prearm(obs)
            + check_track_mode(obs))
    return rows + check_failsafes(obs) + check_limits(obs) + check_signing(obs)


def exit_code(rows: list[Check]) -> int:
    """0 every check ok, 1 a warning or failure."""
    return 0 if all(r.status == OK for r in rows) else 1   # ExitCode.OK / CHECK_FAILED


def fixes(rows: list[Check], params: Mapping[str, float]) -> dict[str, float]:
    """The parameter values --fix would set: from rows that are not ok, for parameters the
    vehicle has, where the value differs."""
    out: dict[str, float] = {}
    for r in rows:
        if r.status == OK:
            continue
        for name, value in r.fix.items():
            if name in params and params[name] != value:
                out[name] = value
    return out
