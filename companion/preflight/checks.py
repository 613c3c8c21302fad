"""The preflight checks, the frontend: pure functions from what the vehicle said to ok / warn / fail.

Each check reads an :class:`Observed` (the heartbeat, the parameters, a few status messages, what
the stream-rate request did, the companion's own settings) and returns :class:`Check` rows: the
parameter or message looked at, its value, what to set and why. A row may carry ``fix``, the
parameter values ``companion preflight --fix`` would set; only what has one right answer for
every rover gets one (failsafe settings), never a vehicle's own limits. Both types are the
profiles' (:mod:`companion.profiles.observed`): the checks that differ between autopilots are
their profile's own (the backends), called here without asking which autopilot it is:

* the frame and its steering kind (``PreflightFacts.frame.check``: ArduPilot's FRAME_CLASS and
  SERVOn_FUNCTION, :mod:`companion.profiles.ardupilot_preflight`; PX4's CA_AIRFRAME,
  :mod:`companion.profiles.px4`), each steering kind's verdict and why its steering profile's;
* the failsafe for a companion that falls silent (``PreflightFacts.failsafe.check``: ArduPilot's
  GCS failsafe, PX4's offboard loss).

The rest is data the profile names (:class:`~companion.profiles.autopilot.PreflightFacts`: the
rate cap's parameter, the inner-loop limits, the top speed, the track mode) read by the checks
below. Facts behind them (``vehicle-interfaces.md``; ArduPilot Rover, PX4 sources):

* HEARTBEAT type 10 is a ground rover, 11 a boat (ArduPilot Rover sends 11 with FRAME_CLASS 2);
* SYS_STATUS's MAV_SYS_STATUS_PREARM_CHECK bit is healthy when the pre-arm checks pass;
* EKF_STATUS_REPORT / ESTIMATOR_STATUS flags: 1 attitude, 2 horizontal velocity, 8 relative and
  16 absolute horizontal position, 1024 uninitialised, 32768 GPS glitching; ArduPilot's EKF
  failsafe trips at FS_EKF_THRESH (0.8) on the variances, ground stations go red there;
* a message rate above 0.8 x SCHED_LOOP_RATE is refused.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from ..profiles.autopilot import TopSpeedParams
from ..profiles.observed import (
    FAIL,
    OK,
    WARN,
    Check,
    Ekf,
    Limits,
    Observed,
    Streams,
    missing,
)

__all__ = ["OK", "WARN", "FAIL", "Check", "Ekf", "Limits", "Observed", "Streams", "run_checks",
           "exit_code", "fixes"]
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


def check_steering(obs: Observed) -> list[Check]:
    """Skid-steer or Ackermann (a steering profile), as the autopilot's frame shows it (the
    profile's ``frame.check``: output functions, an airframe parameter)."""
    return obs.profile.preflight.frame.check(obs)


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
    lost = [label for bit, label in ((EKF_ATTITUDE, "attitude"),
                                        (EKF_VEL_HORIZ, "horizontal velocity"),
                                        (EKF_POS_REL, "relative position")) if not e.flags & bit]
    variances = {"velocity": e.velocity_variance, "position": e.pos_horiz_variance,
                 "compass": e.compass_variance}
    worst = max(variances, key=lambda k: variances[k])
    value = f"flags 0x{e.flags:x}, {worst} variance {variances[worst]:.2f}"
    if e.flags & EKF_UNINITIALIZED or e.flags & EKF_GPS_GLITCHING or lost:
        bad = lost + (["uninitialised"] if e.flags & EKF_UNINITIALIZED else []) \
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
    """The autopilot's failsafe for a companion that falls silent (the profile's
    ``failsafe.check``: ArduPilot's GCS failsafe, PX4's offboard loss)."""
    return obs.profile.preflight.failsafe.check(obs)


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
        absent = missing(name, obs, want, f"{what} of the vehicle model")
        if absent:
            out.append(absent)
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
    absent = missing(f.cruise_speed, obs, "> 0 m/s", f"the speed at {f.cruise_throttle}")
    if absent:
        return absent
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
