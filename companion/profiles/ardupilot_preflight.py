"""ArduPilot Rover's own preflight checks: how its frame shows the steering kind, and its GCS failsafe.

The facts (:class:`ServoFrame`, :class:`GcsFailsafe`) are filled in by :mod:`.ardupilot`'s
profile; ``companion preflight`` (:mod:`companion.preflight.checks`) runs their ``check``:

* the frame: FRAME_CLASS 1 (rover) or 2 (boat), FRAME_TYPE 0 (not omni), and a steering kind's
  SERVOn_FUNCTION values all assigned (skid 73 / 74, Ackermann 26 / 70: the steering profiles');
* the GCS failsafe watches heartbeats of MAV_GCS_SYSID (SYSID_MYGCS before 2025; a range up to
  MAV_GCS_SYSID_HI); MAV_OPTIONS bit 0 (SYSID_ENFORCE before) drops every other system's
  messages, the companion's setpoints included. A companion with its own system id is the
  ground station the failsafe watches; one inside the vehicle's system (the default,
  docs/ground-station.md) is not, and the guided timeout catches its death.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from .observed import FAIL, OK, WARN, Check, Observed, missing, num

if TYPE_CHECKING:
    from .steering import SteeringProfile


# --------------------------------------------------------------------------- the frame

@dataclass(frozen=True)
class ServoFrame:
    """The steering kind shows in the frame class and the output functions (ArduPilot):
    ``class_param`` must be one of ``classes``, ``type_param`` 0, and a steering kind's
    SERVOn_FUNCTION values (:attr:`companion.profiles.steering.SteeringProfile.servo_functions`)
    all assigned."""

    class_param: str
    classes: Mapping[int, str]          # accepted frame classes -> what they are
    type_param: str
    # the output-function parameters (ArduPilot: SERVO1_FUNCTION ... SERVO16_FUNCTION)
    function_params: tuple[str, ...] = tuple(f"SERVO{n}_FUNCTION" for n in range(1, 17))

    def params(self) -> tuple[str, ...]:
        """The parameters that tell the steering kind."""
        return self.function_params

    def steering(self, values: Mapping[str, float]) -> SteeringProfile | None:
        """The steering kind the output functions in ``values`` show, None if none."""
        from . import steering_by_servos  # the registry imports the profiles
        return steering_by_servos({int(v) for k, v in values.items()
                                   if k in self.function_params and v == v})

    def check(self, obs: Observed) -> list[Check]:
        """Skid-steer or Ackermann (a steering profile), from the frame class and the servo
        functions (the paper's model is a differential-drive rover)."""
        from . import STEERING, model_steering, steering_by_servos
        p = obs.params
        classes = " or ".join(f"{k} ({v})" for k, v in self.classes.items())
        absent = missing(self.class_param, obs, classes,
                         "the frame tells a rover from a balance bot")
        if absent:
            return [absent]
        frame_class = int(p[self.class_param])
        servos = _servo_functions(p)
        kind, model = steering_by_servos(set(servos)), model_steering()
        outputs = ", ".join(f"{n} {f}" for s in STEERING.values()
                            for f in s.servo_functions for n in servos.get(f, []))
        name = f"{self.class_param}, SERVOn_FUNCTION"
        if frame_class not in self.classes:
            return [Check(name, FAIL, f"{self.class_param} {frame_class}", classes,
                          "not a rover or boat frame (3 is a balance bot): the companion's model "
                          "does not describe it")]
        frame_type = int(p.get(self.type_param, 0) or 0)
        if frame_type != 0:
            return [Check(name, WARN, f"{self.type_param} {frame_type} (omni)",
                          f"{self.type_param} 0",
                          "an omni frame moves sideways too; the companion commands only speed "
                          "and turn rate")]
        if kind is model:
            return [Check(name, OK, f"{kind.label} ({outputs})", kind.servo_text, kind.why)]
        if kind is not None:
            model_servos = " / ".join(map(str, model.servo_functions))
            return [Check(name, kind.verdict, f"{kind.label} ({outputs})",
                          f"{model.name} steering ({model_servos})", kind.why)]
        either = " or ".join(f"{' and '.join(map(str, s.servo_functions))} ({s.label})"
                             for s in STEERING.values())
        return [Check(name, FAIL, "no throttle outputs" + (f" ({outputs})" if outputs else ""),
                      f"SERVOn_FUNCTION {either}",
                      "no motor output is assigned to throttle: the rover cannot move")]


def _servo_functions(params: Mapping[str, float]) -> dict[int, list[str]]:
    out: dict[int, list[str]] = {}
    for name, value in params.items():
        if name.startswith("SERVO") and name.endswith("_FUNCTION") and math.isfinite(value):
            out.setdefault(int(value), []).append(name)
    return out


# --------------------------------------------------------------------------- the GCS failsafe

@dataclass(frozen=True)
class GcsFailsafe:
    """A failsafe on the ground station's heartbeat (the companion's counts): on / off, what it
    does, after how long, and which system id it watches (several firmware spellings)."""

    enable: str
    action: str
    action_hold: float                  # the value that stops the rover
    action_hold_label: str
    timeout: str
    timeout_range: tuple[float, float]  # s, inclusive
    timeout_fix: float
    sysid_params: tuple[tuple[str, str, str], ...]   # (watched id, its upper bound or '', enforce)
    silent_companion: str               # what happens without the failsafe

    def check(self, obs: Observed) -> list[Check]:
        """The failsafe for a companion that falls silent: its own heartbeat counts when it is
        a system of its own; inside the vehicle's system, the failsafe is the ground
        station's."""
        if obs.vehicle_sysid is not None and obs.companion_sysid == obs.vehicle_sysid:
            return _onboard(obs, self)
        return _own_system(obs, self)

    def sysid_names(self, params: Mapping[str, float]) -> tuple[str, str, str]:
        """(GCS system id parameter, its upper bound or '', enforce parameter) of this
        firmware: the first spelling it has, else the oldest."""
        return next((names for names in self.sysid_params if names[0] in params),
                    self.sysid_params[-1])


def _action(obs: Observed, f: GcsFailsafe) -> Check:
    """The failsafe's action: set, and not "nothing" (both identities' checks)."""
    p = obs.params
    absent = missing(f.action, obs, f.action_hold_label, "what the failsafe does")
    if absent:
        return absent
    if p[f.action] == 0:
        return Check(f.action, WARN, "0 (nothing)", f.action_hold_label,
                     "a failsafe that does nothing leaves the rover driving",
                     {f.action: float(f.action_hold)})
    return Check(f.action, OK, num(p[f.action]), f.action_hold_label,
                 f"the failsafe takes the rover out of {obs.profile.track_mode}")


def _timeout(obs: Observed, f: GcsFailsafe, silent: str, beats: str, lost: str) -> Check:
    """The failsafe's timeout: longer than a few lost 1 Hz heartbeats (``beats`` says whose),
    short enough that ``silent`` / ``lost`` is noticed."""
    lo_t, hi_t = f.timeout_range
    absent = missing(f.timeout, obs, f"{f.timeout_fix:g} s", f"how long {silent} goes unnoticed")
    if absent:
        return absent
    t = obs.params[f.timeout]
    if lo_t <= t <= hi_t:
        return Check(f.timeout, OK, f"{t:g} s", f"{lo_t:g} to {hi_t:g} s",
                     "longer than a few lost 1 Hz heartbeats, short enough to matter")
    return Check(f.timeout, WARN, f"{t:g} s", f"{lo_t:g} to {hi_t:g} s ({f.timeout_fix:g})",
                 f"{beats} each second: under {lo_t:g} s a few lost ones trip it, over "
                 f"{hi_t:g} s {lost} goes unnoticed", {f.timeout: f.timeout_fix})


def _own_system(obs: Observed, f: GcsFailsafe) -> list[Check]:
    """The companion is a system of its own: its heartbeat is a GCS heartbeat."""
    p, out = obs.params, []
    me = obs.companion_sysid
    absent = missing(f.enable, obs, "1", "the GCS failsafe notices a dead companion")
    if absent:
        out.append(absent)
    elif p[f.enable] == 0:
        out.append(Check(f.enable, WARN, "0 (off)", "1",
                         f"the companion's heartbeat (system {me}) is a GCS heartbeat: with "
                         f"the failsafe on, a companion that dies is noticed within "
                         f"{f.timeout} and {f.action} runs; off, {f.silent_companion}",
                         {f.enable: 1.0}))
    else:
        out.append(Check(f.enable, OK, num(p[f.enable]), "1",
                         f"a companion (or ground station) that falls silent triggers {f.action}"))
    out.append(_action(obs, f))
    out.append(_timeout(obs, f, "a silent companion", "the companion sends a heartbeat",
                        "a dead companion"))
    sysid_name, hi_name, enforce_name = f.sysid_names(p)
    absent = missing(sysid_name, obs, f"{me}", "which system the GCS failsafe watches")
    if absent:
        return out + [absent]
    lo = int(p[sysid_name])
    hi = int(p.get(hi_name, 0) or 0) if hi_name else 0
    enforce = (int(p.get(enforce_name, 0) or 0) & 1) if enforce_name else 0
    value = f"{lo}" + (f"..{hi}" if hi > lo else "") + (f", {enforce_name} enforcing"
                                                          if enforce else "")
    want = f"{me} (the companion's system id)"
    if me in range(lo, max(lo, hi) + 1):
        out.append(Check(sysid_name, OK, value, want,
                         "the GCS failsafe and the vehicle listen to the companion"))
    elif enforce:
        out.append(Check(sysid_name, FAIL, value, want,
                         f"{enforce_name} makes the vehicle drop every message from another "
                         "system: the companion's setpoints are ignored",
                         {sysid_name: float(me)}))
    else:
        out.append(Check(sysid_name, WARN, value, want,
                         "the GCS failsafe watches another system: a dead companion goes "
                         "unnoticed", {sysid_name: float(me)}))
    return out


def _onboard(obs: Observed, f: GcsFailsafe) -> list[Check]:
    """The companion is a component of the vehicle's own system (the default, docs/
    ground-station.md): the GCS failsafe watches the ground station alone, and the companion's
    own death is caught by the guided timeout, not by this failsafe."""
    p, out = obs.params, []
    me = obs.companion_sysid
    absent = missing(f.enable, obs, "1", "the GCS failsafe notices a lost ground station")
    if absent:
        out.append(absent)
    elif p[f.enable] == 0:
        out.append(Check(f.enable, WARN, "0 (off)", "1",
                         "the ground station's link can be lost unnoticed; the companion "
                         f"(system {me}, the vehicle's own) does not stand in for it",
                         {f.enable: 1.0}))
    else:
        out.append(Check(f.enable, OK, num(p[f.enable]), "1",
                         f"a lost ground station triggers {f.action}; the companion's heartbeat "
                         "does not keep it from firing"))
    out.append(_action(obs, f))
    out.append(_timeout(obs, f, "a lost ground station", "a ground station heart-beats",
                        "a lost one"))
    sysid_name, hi_name, _enforce_name = f.sysid_names(p)
    absent = missing(sysid_name, obs, "the ground station's id (255)",
                     "which system the GCS failsafe watches")
    if absent:
        return out + [absent]
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
