"""The preflight checks: pure functions from what the vehicle said to ok / warn / fail.

Each check reads an :class:`Observed` (the heartbeat, the parameters, a few status messages, what
the stream-rate request did, the companion's own settings) and returns :class:`Check` rows: the
parameter or message looked at, its value, what to set and why. A row may carry ``fix``, the
parameter values ``companion preflight --fix`` would set; only what has one right answer for
every rover gets one (failsafe settings), never a vehicle's own limits.

Facts behind the rules (``vehicle-interfaces.md``; ArduPilot Rover, PX4 sources):

* HEARTBEAT type 10 is a ground rover, 11 a boat (ArduPilot Rover sends 11 with FRAME_CLASS 2);
* skid steering is SERVOn_FUNCTION 73 (throttle left) and 74 (throttle right); Ackermann is 26
  (ground steering) with 70 (throttle); PX4: CA_AIRFRAME 6 differential, 5 Ackermann, 13 mecanum;
* SYS_STATUS's MAV_SYS_STATUS_PREARM_CHECK bit is healthy when the pre-arm checks pass;
* EKF_STATUS_REPORT / ESTIMATOR_STATUS flags: 1 attitude, 2 horizontal velocity, 8 relative and
  16 absolute horizontal position, 1024 uninitialised, 32768 GPS glitching; ArduPilot's EKF
  failsafe trips at FS_EKF_THRESH (0.8) on the variances, ground stations go red there;
* the GCS failsafe watches heartbeats of MAV_GCS_SYSID (SYSID_MYGCS before 2025; a range up to
  MAV_GCS_SYSID_HI); MAV_OPTIONS bit 0 (SYSID_ENFORCE before) drops every other system's
  messages, the companion's setpoints included;
* a message rate above 0.8 x SCHED_LOOP_RATE is refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

OK, WARN, FAIL = "ok", "warn", "fail"
ARDUPILOT, PX4 = "ardupilot", "px4"
MAV_TYPE_GROUND_ROVER, MAV_TYPE_SURFACE_BOAT = 10, 11
PREARM_BIT = 0x10000000                     # MAV_SYS_STATUS_PREARM_CHECK
EKF_ATTITUDE, EKF_VEL_HORIZ, EKF_POS_REL, EKF_POS_ABS = 1, 2, 8, 16
EKF_UNINITIALIZED, EKF_GPS_GLITCHING = 1024, 32768
EKF_WARN, EKF_FAIL = 0.5, 0.8               # variance ratios (FS_EKF_THRESH's default is 0.8)
RATE_CAP = 0.8                              # streams up to 0.8 x SCHED_LOOP_RATE
LIMIT_TOLERANCE = 0.25                      # vehicle file vs autopilot, relative
SKID = (73, 74)                             # SERVOn_FUNCTION throttle left / right
ACKERMANN = (26, 70)                        # ground steering, throttle
TRACK_MODE = {ARDUPILOT: "GUIDED", PX4: "OFFBOARD"}
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
    autopilot: str                          # ARDUPILOT or PX4
    mav_type: int
    modes: frozenset[str]                   # the mode names the vehicle type has
    armed: bool = False
    mavlink_version: int = 2                # of the vehicle's frames
    signed: bool = False                    # the vehicle's frames carry a signature
    signing_key: bool = False               # the companion signs (and verified the vehicle's)
    serial: bool = False                    # the link is a serial device (a wire)
    companion_sysid: int = 255
    params: Mapping[str, float] = field(default_factory=dict)
    sensors: tuple[int, int, int] | None = None      # SYS_STATUS present, enabled, health
    prearm_texts: tuple[str, ...] = ()
    ekf: Ekf | None = None
    origin: tuple[float, float] | None = None        # GPS_GLOBAL_ORIGIN lat, lon (deg)
    streams: Streams | None = None
    limits: Limits | None = None


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
    """Skid-steer or Ackermann, from the frame and the servo functions (the paper's model is a
    differential-drive rover)."""
    p = obs.params
    if obs.autopilot == PX4:
        missing = _param("CA_AIRFRAME", obs, "6 (Rover (Differential))",
                         "the frame tells skid steering from Ackermann")
        if missing:
            return [missing]
        frame = int(p["CA_AIRFRAME"])
        kinds = {6: "skid-steer (Rover (Differential))", 5: "Ackermann (Rover (Ackermann))",
                 13: "mecanum (Rover (Mecanum))"}
        value = f"{kinds.get(frame, 'not a rover')} (CA_AIRFRAME {frame})"
        if frame == 6:
            return [Check("CA_AIRFRAME", OK, value, "6", "a differential-drive rover: the "
                          "vehicle model's kind")]
        status = WARN if frame in kinds else FAIL
        return [Check("CA_AIRFRAME", status, value, "6 (Rover (Differential))",
                      _ACKERMANN_WHY if frame == 5 else
                      "the companion's model is a differential-drive rover"
                      if frame in kinds else "the airframe is not a rover")]
    missing = _param("FRAME_CLASS", obs, "1 (rover) or 2 (boat)",
                     "the frame tells a rover from a balance bot")
    if missing:
        return [missing]
    frame_class = int(p["FRAME_CLASS"])
    servos = _servo_functions(p)
    skid = all(f in servos for f in SKID)
    ackermann = all(f in servos for f in ACKERMANN)
    outputs = ", ".join(f"{n} {f}" for f in (*SKID, *ACKERMANN) for n in servos.get(f, []))
    name = "FRAME_CLASS, SERVOn_FUNCTION"
    if frame_class not in (1, 2):
        return [Check(name, FAIL, f"FRAME_CLASS {frame_class}", "1 (rover) or 2 (boat)",
                      "not a rover or boat frame (3 is a balance bot): the companion's model "
                      "does not describe it")]
    frame_type = int(p.get("FRAME_TYPE", 0) or 0)
    if frame_type != 0:
        return [Check(name, WARN, f"FRAME_TYPE {frame_type} (omni)", "FRAME_TYPE 0",
                      "an omni frame moves sideways too; the companion commands only speed "
                      "and turn rate")]
    if skid:
        return [Check(name, OK, f"skid-steer ({outputs})", "throttle left 73 / right 74",
                      "a differential-drive rover: the vehicle model's kind")]
    if ackermann:
        return [Check(name, WARN, f"Ackermann ({outputs})", "skid steering (73 / 74)",
                      _ACKERMANN_WHY)]
    return [Check(name, FAIL, "no throttle outputs" + (f" ({outputs})" if outputs else ""),
                  "SERVOn_FUNCTION 73 and 74 (skid) or 26 and 70 (Ackermann)",
                  "no motor output is assigned to throttle: the rover cannot move")]


_ACKERMANN_WHY = ("an Ackermann rover cannot turn in place and its turn rate follows its "
                  "speed; the paper's model is a differential drive: identify the vehicle "
                  "(companion identify) and keep paths within its turning circle")


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
    loop = obs.params.get("SCHED_LOOP_RATE")
    if refused:
        need = math.ceil(asked / RATE_CAP)
        fix = ({"SCHED_LOOP_RATE": float(need)}
               if loop is not None and obs.autopilot == ARDUPILOT and loop < need else {})
        extra = (f"; SCHED_LOOP_RATE {loop:g} allows {RATE_CAP * loop:g} Hz, {need} allows "
                 f"{asked:g} Hz (after a reboot)" if fix else "")
        return [Check(name, WARN, value + f", refused for {', '.join(refused)}",
                      f"{want}" + (f" (SCHED_LOOP_RATE {need})" if fix else ""),
                      "the vehicle refused the rate; the companion falls back to a slower one"
                      + extra, fix)]
    slow = [k for k, v in measured.items() if v < 0.8 * asked]
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
    mode = TRACK_MODE.get(obs.autopilot, "GUIDED")
    if mode in obs.modes:
        return [Check(mode, OK, "available", f"{mode} available",
                      "the mode in which the vehicle follows the companion's setpoints")]
    return [Check(mode, FAIL, "not among the vehicle's modes", f"{mode} available",
                  "the vehicle has no mode that follows external setpoints")]


# --------------------------------------------------------------------------- failsafes

def _gcs_sysid_names(params: Mapping[str, float]) -> tuple[str, str, str | None]:
    """(GCS system id parameter, its upper bound or '', enforce parameter) of this firmware."""
    if "MAV_GCS_SYSID" in params:
        return "MAV_GCS_SYSID", "MAV_GCS_SYSID_HI", "MAV_OPTIONS"
    return "SYSID_MYGCS", "", "SYSID_ENFORCE"


def check_failsafes_ardupilot(obs: Observed) -> list[Check]:
    p, out = obs.params, []
    me = obs.companion_sysid
    missing = _param("FS_GCS_ENABLE", obs, "1", "the GCS failsafe notices a dead companion")
    if missing:
        out.append(missing)
    elif p["FS_GCS_ENABLE"] == 0:
        out.append(Check("FS_GCS_ENABLE", WARN, "0 (off)", "1",
                         f"the companion's heartbeat (system {me}) is a GCS heartbeat: with "
                         "the failsafe on, a companion that dies is noticed within "
                         "FS_GCS_TIMEOUT and FS_ACTION runs; off, the rover keeps its last "
                         "setpoint for 3 s (the guided timeout), then stops armed in GUIDED",
                         {"FS_GCS_ENABLE": 1.0}))
    else:
        out.append(Check("FS_GCS_ENABLE", OK, _num(p["FS_GCS_ENABLE"]), "1",
                         "a companion (or ground station) that falls silent triggers FS_ACTION"))
    missing = _param("FS_ACTION", obs, "2 (Hold)", "what the failsafe does")
    if missing:
        out.append(missing)
    elif p["FS_ACTION"] == 0:
        out.append(Check("FS_ACTION", WARN, "0 (nothing)", "2 (Hold)",
                         "a failsafe that does nothing leaves the rover driving",
                         {"FS_ACTION": 2.0}))
    else:
        out.append(Check("FS_ACTION", OK, _num(p["FS_ACTION"]), "2 (Hold)",
                         "the failsafe takes the rover out of GUIDED"))
    missing = _param("FS_GCS_TIMEOUT", obs, "5 s", "how long a silent companion goes unnoticed")
    if missing:
        out.append(missing)
    else:
        t = p["FS_GCS_TIMEOUT"]
        if 2.0 <= t <= 10.0:
            out.append(Check("FS_GCS_TIMEOUT", OK, f"{t:g} s", "2 to 10 s",
                             "longer than a few lost 1 Hz heartbeats, short enough to matter"))
        else:
            out.append(Check("FS_GCS_TIMEOUT", WARN, f"{t:g} s", "2 to 10 s (5)",
                             "the companion sends a heartbeat each second: under 2 s a few "
                             "lost ones trip it, over 10 s a dead companion goes unnoticed",
                             {"FS_GCS_TIMEOUT": 5.0}))
    sysid_name, hi_name, enforce_name = _gcs_sysid_names(p)
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


def check_failsafes_px4(obs: Observed) -> list[Check]:
    p, out = obs.params, []
    missing = _param("COM_OF_LOSS_T", obs, "1 s or less", "how long PX4 follows a lost stream")
    if missing:
        out.append(missing)
    else:
        t = p["COM_OF_LOSS_T"]
        ok = 0.0 < t <= 1.0
        out.append(Check("COM_OF_LOSS_T", OK if ok else WARN, f"{t:g} s", "0 < t <= 1 s",
                         "PX4 holds the last setpoint this long after the companion falls "
                         "silent" + ("" if ok else ": the rover drives blind meanwhile"),
                         {} if ok else {"COM_OF_LOSS_T": 1.0}))
    missing = _param("COM_OBL_RC_ACT", obs, "5 (Hold)", "what PX4 does when offboard is lost")
    if missing:
        out.append(missing)
    else:
        act = int(p["COM_OBL_RC_ACT"])
        names = {0: "Position", 1: "Altitude", 2: "Stabilized/Manual", 3: "Return", 4: "Land",
                 5: "Hold", 6: "Terminate", 7: "Disarm"}
        value = f"{act} ({names.get(act, '?')})"
        if act == 5:
            out.append(Check("COM_OBL_RC_ACT", OK, value, "5 (Hold)",
                             "a lost companion leaves the rover stopped"))
        else:
            out.append(Check("COM_OBL_RC_ACT", WARN, value, "5 (Hold)",
                             "on offboard loss the rover should stop where it is, not wait for "
                             "a pilot's sticks or drive away", {"COM_OBL_RC_ACT": 5.0}))
    return out


# --------------------------------------------------------------------------- inner loops

# (parameter, unit, to SI, Limits field, what the model does with it, 0 allowed)
_AP_LIMITS = (
    ("ATC_ACCEL_MAX", "m/s^2", 1.0, "max_accel", "the speed loop's acceleration limit", False),
    ("ATC_DECEL_MAX", "m/s^2", 1.0, "max_decel", "the speed loop's deceleration limit", True),
    ("ATC_STR_RAT_MAX", "deg/s", math.pi / 180, "max_yaw_rate", "the turn-rate limit", False),
    ("ATC_STR_ACC_MAX", "deg/s^2", math.pi / 180, "max_yaw_accel",
     "the turn-rate loop's acceleration limit", False),
)


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
    """The inner-loop limits the vehicle model starts from (companion.ident.priors)."""
    if obs.autopilot != ARDUPILOT:
        return [Check("inner-loop limits", WARN, "not read", "the rover's speed and turn-rate "
                      "limits", "PX4's rover limit parameters differ between releases: "
                      "identify the vehicle (companion identify) for its model")]
    p, out, lim = obs.params, [], obs.limits
    for name, unit, scale, attr, what, zero_ok in _AP_LIMITS:
        want = f">= 0 {unit} (0: as ATC_ACCEL_MAX)" if zero_ok else f"> 0 {unit}"
        missing = _param(name, obs, want, f"{what} of the vehicle model")
        if missing:
            out.append(missing)
            continue
        v = p[name]
        value = f"{v:g} {unit}"
        if v < 0 or (v == 0 and not zero_ok):
            out.append(Check(name, WARN, value + (" (no limit)" if v == 0 else ""),
                             want, f"{what}: without it the vehicle answers a step "
                             "at once and the model's rate limit is a guess"))
            continue
        if lim is not None:
            model = getattr(lim, attr)
            ap = (p["ATC_ACCEL_MAX"] if v == 0 and attr == "max_decel" else v) * scale
            row = _compare(name, ap, model, scale, unit, value, lim)
            if row is not None:
                out.append(row)
                continue
        out.append(Check(name, OK, value, want, f"{what}: the vehicle model starts from it"))
    out.append(_top_speed(obs))
    return out


def _top_speed(obs: Observed) -> Check:
    p = obs.params
    name = "WP_SPEED, CRUISE_SPEED / CRUISE_THROTTLE"
    missing = _param("CRUISE_SPEED", obs, "> 0 m/s", "the speed at CRUISE_THROTTLE")
    if missing:
        return missing
    cruise, throttle = p["CRUISE_SPEED"], p.get("CRUISE_THROTTLE", 0.0)
    wp = p.get("WP_SPEED", 0.0)
    if not (cruise > 0 and 0 < throttle <= 100):
        return Check(name, WARN, f"CRUISE_SPEED {cruise:g}, CRUISE_THROTTLE {throttle:g}",
                     "CRUISE_SPEED > 0 at CRUISE_THROTTLE 1..100 %",
                     "the throttle feed-forward and the model's top speed come from these")
    full = cruise * 100.0 / throttle
    top = wp if 0 < wp <= full else full
    value = f"top speed {top:.3g} m/s (WP_SPEED {wp:g}, full throttle {full:.3g})"
    if obs.limits is not None:
        row = _compare(name, top, obs.limits.max_speed, 1.0, "m/s", value, obs.limits)
        if row is not None:
            return row
    return Check(name, OK, value, "> 0", "GUIDED holds speed setpoints to this")


# --------------------------------------------------------------------------- all of them

def run_checks(obs: Observed) -> list[Check]:
    rows = (check_vehicle(obs) + check_steering(obs) + check_protocol(obs)
            + check_streams(obs) + check_origin(obs) + check_ekf(obs) + check_prearm(obs)
            + check_track_mode(obs))
    rows += check_failsafes_px4(obs) if obs.autopilot == PX4 else check_failsafes_ardupilot(obs)
    return rows + check_limits(obs) + check_signing(obs)


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
