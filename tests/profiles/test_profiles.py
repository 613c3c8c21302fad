"""Autopilot and steering profiles: every difference lives in companion/profiles/, nowhere else.

The code of ``companion/`` and ``sitl_plant/`` is read with ``ast``: any comparison or membership
test against an autopilot's or a steering kind's name or constant (``"px4"``, ``PX4``,
``Autopilot.PX4``, ``MAV_AUTOPILOT_PX4``, ``msg.autopilot == 12``, ``"ackermann"``, ...), any
table keyed by them and any ``if px4:`` outside ``companion/profiles/`` fails with the file and
line. Then the profiles themselves: each registered one fills the interface, its mode table
round-trips (name -> DO_SET_MODE -> custom_mode -> name) and agrees with pymavlink's, and a new
profile is one registration away from the flags, the link and preflight.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import math
from pathlib import Path

import pytest

import companion.profiles as profiles
from companion.profiles import ackermann, ardupilot, px4, skid
from companion.profiles.priors import Priors
from companion.sim.plant import RoverParams

# the interface module (the registry's look-up function is ``profiles.autopilot_named``)
iface = importlib.import_module("companion.profiles.autopilot")
ROOT = Path(__file__).resolve().parents[2]
PROFILES_DIR = ROOT / "companion" / "profiles"


# --------------------------------------------------------------------------- reading the code

def forbidden() -> tuple[set[str], set[str], set[int]]:
    """(names as strings, identifiers, MAV_AUTOPILOT ids) that say which autopilot or steering
    kind it is, from the registry (a new profile is covered the day it is registered)."""
    words = {p.name.lower() for p in profiles.AUTOPILOTS.values()}
    words |= {p.label.lower() for p in profiles.AUTOPILOTS.values()}
    words |= {s.name.lower() for s in profiles.STEERING.values()}
    words |= {s.label.lower() for s in profiles.STEERING.values()}
    words.add("ardupilotmega")
    idents = {w.replace("-", "_") for w in words}
    idents |= {i.upper() for i in idents} | {f"is_{i}" for i in idents}
    idents |= {"MAV_AUTOPILOT_ARDUPILOTMEGA", "MAV_AUTOPILOT_PX4"}
    ids = {i for p in profiles.AUTOPILOTS.values() for i in p.mav_autopilot}
    return words, idents, ids


def _ident(node: ast.AST) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return None


def name_tests(source: str) -> list[tuple[int, str]]:
    """(line, code) of every test of an autopilot's or steering kind's identity in ``source``."""
    words, idents, ids = forbidden()

    def named(node: ast.AST) -> bool:
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            return node.value.lower() in words
        if _ident(node) in idents:
            return True
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            return any(named(e) for e in node.elts)
        if isinstance(node, ast.Call) and _ident(node.func) in ("set", "frozenset", "tuple"):
            return any(named(a) for a in node.args)
        return False

    def autopilot_id(a: ast.AST, b: ast.AST) -> bool:
        return (isinstance(b, ast.Constant) and type(b.value) is int and b.value in ids
                and (_ident(a) or "").lower().endswith("autopilot"))

    hits = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            if any(named(o) for o in operands) or any(
                    autopilot_id(a, b) for a in operands for b in operands if a is not b):
                hits.append(node)
        elif isinstance(node, ast.Dict) and any(k is not None and named(k) for k in node.keys):
            hits.append(node)
        elif isinstance(node, ast.MatchValue) and named(node.value):
            hits.append(node)
        elif isinstance(node, (ast.If, ast.IfExp, ast.While, ast.Assert)):
            test = node.test
            parts = (test.values if isinstance(test, ast.BoolOp)
                     else [test.operand] if isinstance(test, ast.UnaryOp) else [test])
            if any(_ident(p) in idents for p in parts):
                hits.append(node)
        elif isinstance(node, ast.BoolOp) and any(_ident(v) in idents for v in node.values):
            hits.append(node)
    return sorted({(n.lineno, ast.get_source_segment(source, n).splitlines()[0]) for n in hits})


def code_files() -> list[Path]:
    files = [*(ROOT / "companion").rglob("*.py"), *(ROOT / "sitl_plant").rglob("*.py")]
    return sorted(p for p in files if "__pycache__" not in p.parts
                  and PROFILES_DIR not in p.parents)


def test_no_code_outside_the_profiles_asks_which_autopilot_or_steering_kind_it_is():
    bad = [f"{path.relative_to(ROOT)}:{line}: {code}"
           for path in code_files() for line, code in name_tests(path.read_text())]
    assert not bad, ("ask the profile instead (companion/profiles/, docs/design/profiles.md):\n"
                     + "\n".join(bad))


@pytest.mark.parametrize("code", [
    'if vehicle.autopilot == "px4": pass',
    'x = a if autopilot != "ardupilot" else b',
    "ok = obs.autopilot in (ARDUPILOT, 'other')",
    "ok = v.autopilot is Autopilot.PX4",
    "ok = msg.autopilot == 12",
    "ok = hb.autopilot != 3",
    "MODES = {PX4: 'OFFBOARD', ARDUPILOT: 'GUIDED'}",
    "if self.px4 and ready: pass",
    "if not px4: pass",
    "ok = kind == 'ackermann'",
    "ok = all(f in servos for f in SKID) and frame in SKID",
    "match name:\n    case 'px4': pass",
    "ok = dialect == 'ardupilotmega'",
])
def test_the_reader_finds_each_way_of_asking(code):
    assert name_tests(code), code


@pytest.mark.parametrize("code", [
    "mode = vehicle.profile.track_mode",
    "ok = v.profile.offboard_warmup is not None",
    'link = open_connection(url, dialect="ardupilotmega")',
    "ok = msg.autopilot in v.profile.mav_autopilot",
    "ok = msg.type == 12",
    'ok = args.preset == "ardupilot-skid"',
])
def test_the_reader_lets_the_profile_answer(code):
    assert not name_tests(code), code


# --------------------------------------------------------------------------- the registry

def test_registry_names_ids_and_lookups():
    assert list(profiles.AUTOPILOTS) == ["ardupilot", "px4"]
    assert list(profiles.STEERING) == ["skid", "ackermann"]
    assert profiles.autopilot_named("px4") is px4.PROFILE
    with pytest.raises(KeyError):
        profiles.autopilot_named("betaflight")
    assert profiles.from_heartbeat(3) is ardupilot.PROFILE
    assert profiles.from_heartbeat(12) is px4.PROFILE
    assert profiles.from_heartbeat(0) is None and profiles.from_heartbeat(8) is None
    assert profiles.DEFAULT_AUTOPILOT == "ardupilot"
    assert profiles.default_autopilot() is ardupilot.PROFILE
    # a vehicle model known by itself: PX4's course loop (its model field) says PX4
    assert profiles.autopilot_of_model(RoverParams()) is ardupilot.PROFILE
    assert profiles.autopilot_of_model(RoverParams(course_gain=2.0)) is px4.PROFILE
    params = profiles.prior_params()
    assert set(params) == set(ardupilot.PRIOR_PARAMS) | set(px4.PRIOR_PARAMS)
    assert len(params) == len(set(params))
    assert profiles.model_steering() is skid.PROFILE
    assert profiles.steering_by_airframe(5) is ackermann.PROFILE
    assert profiles.steering_by_airframe(13) is None
    assert profiles.steering_by_servos({70, 26, 1}) is ackermann.PROFILE
    assert profiles.steering_by_servos({73, 74, 26, 70}) is skid.PROFILE   # skid wins
    assert profiles.steering_by_servos({73}) is None


def test_mavlink_numbers_are_pymavlinks():
    from pymavlink.dialects.v20 import ardupilotmega as m
    assert (iface.MAV_AUTOPILOT_ARDUPILOTMEGA, iface.MAV_AUTOPILOT_PX4) == (
        m.MAV_AUTOPILOT_ARDUPILOTMEGA, m.MAV_AUTOPILOT_PX4)
    assert (iface.MAV_TYPE_GROUND_ROVER, iface.MAV_TYPE_SURFACE_BOAT) == (
        m.MAV_TYPE_GROUND_ROVER, m.MAV_TYPE_SURFACE_BOAT)
    assert (iface.MAV_FRAME_LOCAL_NED, iface.MAV_FRAME_BODY_NED) == (
        m.MAV_FRAME_LOCAL_NED, m.MAV_FRAME_BODY_NED)
    for name in ("CUSTOM_MODE_ENABLED", "AUTO_ENABLED", "GUIDED_ENABLED", "STABILIZE_ENABLED",
                 "MANUAL_INPUT_ENABLED", "SAFETY_ARMED"):
        assert getattr(iface, f"FLAG_{name}") == getattr(m, f"MAV_MODE_FLAG_{name}")
    assert (iface.MAV_RESULT_DENIED, iface.MAV_RESULT_FAILED) == (m.MAV_RESULT_DENIED,
                                                                  m.MAV_RESULT_FAILED)
    assert (iface.PARAM_INT8, iface.PARAM_INT16, iface.PARAM_INT32, iface.PARAM_REAL32) == (
        m.MAV_PARAM_TYPE_INT8, m.MAV_PARAM_TYPE_INT16, m.MAV_PARAM_TYPE_INT32,
        m.MAV_PARAM_TYPE_REAL32)


# --------------------------------------------------------------------------- each autopilot

AUTOPILOTS = list(profiles.AUTOPILOTS.values())
ids = [p.name for p in AUTOPILOTS]


@pytest.mark.parametrize("p", AUTOPILOTS, ids=ids)
def test_every_autopilot_profile_fills_the_interface(p):
    assert profiles.AUTOPILOTS[p.name] is p and p.label
    for f in dataclasses.fields(p):
        value = getattr(p, f.name)
        # None where the autopilot has no such thing: no MAV_TYPE restriction, no offboard
        # warm-up, no guided sub-mode inside a mission (auto_mode: PX4)
        assert value is not None or f.name in ("mode_types", "offboard_warmup",
                                               "auto_mode"), f.name
    assert p.mav_autopilot and all(type(i) is int for i in p.mav_autopilot)
    table = p.modes
    assert len(table.names()) == len(table.modes) == len({m.custom_mode for m in table.modes})
    for name in (p.track_mode, p.hold_mode, p.plant.initial_mode, *p.plant.modes,
                 *p.plant.unsettable):
        assert table.by_name(name) is not None, name
    assert p.track_mode in p.plant.modes and p.hold_mode in p.plant.modes
    assert p.offboard_warmup is None or p.offboard_warmup > 0
    assert p.auto_mode is None or table.by_name(p.auto_mode) is not None
    sp = p.setpoint
    # bit 11 ignores the yaw rate: set exactly when the autopilot gets the velocity vector
    assert bool(sp.type_mask & (1 << 11)) == sp.velocity_vector
    assert sp.type_mask & 0b111 == 0b111 and not sp.type_mask & (0b11 << 3)   # vx, vy only
    # preflight facts: the autopilot's own checks of its frame and failsafe, names that are
    # parameters
    pf = p.preflight
    assert pf.frame.params() and callable(pf.frame.check) and callable(pf.failsafe.check)
    assert pf.frame.steering({}) is None
    assert pf.limits or pf.limits_unread
    from companion.preflight.checks import Limits
    limit_fields = {f.name for f in dataclasses.fields(Limits)}
    assert all(lp.field in limit_fields for lp in pf.limits)
    assert pf.estimator_messages
    # identification: priors from nothing and from every parameter it reads
    assert p.ident.params and p.ident.headroom >= 1.0 and p.ident.params_label
    empty = p.priors_from({})
    assert isinstance(empty, Priors) and isinstance(empty.params, RoverParams)
    assert empty.params.velocity_vector == sp.velocity_vector    # the model fits the setpoints
    full = p.priors_from({name: 1.0 for name in p.ident.params} | {"SOMETHING_ELSE": 7.0})
    assert full.source and not any(v is not None and math.isnan(v)
                                   for v in dataclasses.astuple(full.params))
    # the plant serves a parameter list the ParamTable takes
    served = p.plant.params(RoverParams.paper(), 50.0, 1, 0.5)
    assert served and all(isinstance(n, str) and len(n) <= 16 for n, _, _ in served)
    assert all(t in (1, 2, 3, 4, 5, 6, 9) for _, _, t in served)
    assert p.plant.mode_refused in (iface.MAV_RESULT_DENIED, iface.MAV_RESULT_FAILED)
    assert len(p.plant.arm_texts) == 2


@pytest.mark.parametrize("p", AUTOPILOTS, ids=ids)
def test_mode_tables_round_trip(p):
    for mode in p.modes.modes:
        param1, param2, param3 = p.set_mode_params(mode)
        assert int(param1) & iface.FLAG_CUSTOM_MODE_ENABLED
        assert p.requested_mode(param2, param3) == mode.custom_mode, mode
        base = iface.FLAG_CUSTOM_MODE_ENABLED | mode.base_flags
        assert p.mode_name(p.modes, base, mode.custom_mode) == mode.name
        assert p.mode_name(p.modes, base | iface.FLAG_SAFETY_ARMED, mode.custom_mode) == mode.name
        assert p.mode_number(mode.name) == mode.custom_mode
    assert p.requested_mode(math.nan, 0.0) is None
    assert p.requested_mode(math.inf, 0.0) is None
    with pytest.raises(KeyError):
        p.mode_number("NO_SUCH_MODE")


def test_mode_tables_are_pymavlinks():
    """The link names modes as pymavlink did before the profiles had tables: the same names for
    the same numbers, and the same DO_SET_MODE parameters."""
    from pymavlink import mavutil
    assert {m.custom_mode: m.name for m in ardupilot.MODES.modes} == mavutil.mode_mapping_rover
    assert {m.name: (iface.FLAG_CUSTOM_MODE_ENABLED | m.base_flags,
                     *(int(x) for x in px4.set_mode_params(m)[1:]))
            for m in px4.MODES.modes} == mavutil.px4_map
    ap = ardupilot.PROFILE
    assert ap.modes_for(10) is ap.modes and ap.modes_for(11) is ap.modes
    assert ap.modes_for(2).modes == ()          # a copter's modes are another table
    assert px4.PROFILE.modes_for(2) is px4.MODES


@pytest.mark.parametrize("p, mav_type", [(ardupilot.PROFILE, 10), (ardupilot.PROFILE, 11),
                                         (px4.PROFILE, 10)], ids=["ardupilot", "boat", "px4"])
def test_heartbeat_mode_names_are_pymavlinks(p, mav_type):
    from pymavlink import mavutil
    from pymavlink.dialects.v20 import ardupilotmega as m
    mav = m.MAVLink(None)
    words = [w for w in range(20)] + [
        (main << 16) | (sub << 24) | low for main in range(10) for sub in range(10)
        for low in (0, 7)]
    for word in words:
        for base in (0, 1, 1 | 128, 81, 29):
            hb = mav.heartbeat_encode(mav_type, p.mav_autopilot[0], base, word, 4)
            assert p.mode_name(p.modes_for(mav_type), base, word) == mavutil.mode_string_v10(hb)


# --------------------------------------------------------------------------- each steering kind

@pytest.mark.parametrize("s", list(profiles.STEERING.values()), ids=list(profiles.STEERING))
def test_every_steering_profile_fills_the_interface(s):
    assert profiles.STEERING[s.name] is s and s.label and s.why and s.servo_text
    assert s.verdict in ("ok", "warn")
    assert s.servo_functions and all(type(f) is int for f in s.servo_functions)
    model = {f.name for f in dataclasses.fields(RoverParams)}
    assert s.model_fields and set(s.model_fields) <= model
    from companion.preflight.checks import OK, WARN
    assert s.verdict in (OK, WARN)


def test_steering_kinds_do_not_overlap():
    kinds = list(profiles.STEERING.values())
    assert len({s.airframe for s in kinds}) == len(kinds)
    functions = [f for s in kinds for f in s.servo_functions]
    assert len(set(functions)) == len(functions)
    assert [s.verdict for s in kinds].count("ok") == 1
    assert skid.PROFILE.turns_in_place and not ackermann.PROFILE.turns_in_place


# --------------------------------------------------------------------------- adding one

def test_a_registered_profile_reaches_the_flags_the_link_and_preflight(monkeypatch):
    """Adding an autopilot is a module and a line in the registry: nothing else names it."""
    clone = dataclasses.replace(px4.PROFILE, name="px4-clone", label="PX4 clone",
                                mav_autopilot=(99,))
    monkeypatch.setitem(profiles.AUTOPILOTS, clone.name, clone)
    assert profiles.from_heartbeat(99) is clone
    from sitl_plant.cli import build_parser, config_from_args
    args = build_parser().parse_args(["--autopilot", "px4-clone"])
    assert config_from_args(args).vehicle.autopilot is clone
    import argparse

    from companion.commands import demo
    sub = argparse.ArgumentParser().add_subparsers()
    demo.register(sub)
    assert "px4-clone" in next(a for a in sub.choices["demo"]._actions
                               if a.dest == "autopilot").choices
    from companion.preflight.checks import Observed, run_checks
    rows = {r.name: r for r in run_checks(Observed(
        autopilot="px4-clone", mav_type=10, modes=frozenset({"OFFBOARD", "LOITER"}),
        params={"CA_AIRFRAME": 6, "COM_OF_LOSS_T": 0.5, "COM_OBL_RC_ACT": 5}))}
    assert rows["CA_AIRFRAME"].status == "ok" and rows["OFFBOARD"].status == "ok"
    assert "PX4 clone holds the last setpoint" in rows["COM_OF_LOSS_T"].why
