"""Random TOML and random .plan JSON: the loader gives a valid Mission or a clean UserError.

Random documents are mostly built by mutating valid ones (a changed value, a removed or added
key), so the checks deep inside the loader are reached, not just the first type test.
"""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from companion import mission as missions
from companion.errors import UserError

SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])

VALID_TOML = [
    {"name": "c", "laps": 1, "trajectory": {"kind": "circle", "radius": 5.0, "speed": 1.0},
     "limits": {"max_speed": 2.0, "max_yaw_rate": 1.0}},
    {"duration": 20.0, "rate_hz": 40, "trajectory": {"kind": "ellipse", "f_r": 0.08},
     "gains": {"filter": {"k_df": 200.0, "lambda_f": 40.0}, "pzc": {"k_dc": 4.0, "lambda_c": 2.0}},
     "vehicle": {"d_cen": 0.3, "w_c": 20.0}},
    {"trajectory": {"kind": "figure8", "length": 10.0, "width": 4.0, "period": 30.0}},
    {"trajectory": {"kind": "polyline", "speed": 1.0, "corner_radius": 1.0,
                    "points": [[0, 0], [10, 0], [10, 5], [0, 5]]}},
    {"trajectory": {"kind": "waypoints", "waypoints": [[0, 0, 0], [10, 5, 1], [20, 8, 6]]},
     "limits": {"max_speed": 2.0}},
    {"frame": "geodetic", "origin": [-35.36, 149.16],
     "trajectory": {"kind": "line", "end": [10.0, 3.0], "speed": 1.0}},
]

scalars = st.one_of(
    st.integers(-10**20, 10**20), st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-100, 100), st.booleans(), st.text(max_size=8),
    st.sampled_from(["circle", "ellipse", "polyline", "waypoints", "line", "figure8", "plan",
                     "start", "local", "geodetic", "cw", "ccw", ""]))
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(min_size=1, max_size=6), inner,
                                                 max_size=3)), max_leaves=8)
KEYS = ["name", "description", "frame", "origin", "duration", "laps", "rate_hz", "gains_file",
        "gains", "limits", "vehicle", "trajectory", "kind", "radius", "speed", "center", "f_r",
        "points", "waypoints", "closed", "period", "length", "width", "corner_radius", "accel",
        "max_speed", "max_yaw_rate", "filter", "pzc", "k_df", "k_dc", "w_c", "d_cen", "file",
        "direction", "start_bearing_deg", "end", "start", "heading_deg", "x"]


@st.composite
def mutated(draw, bases):
    """A valid document with a few random changes at random places."""
    doc = json.loads(json.dumps(draw(st.sampled_from(bases))))
    for _ in range(draw(st.integers(1, 3))):
        tables = [doc]
        stack = [doc]
        while stack:   # every dict and list in the document
            node = stack.pop()
            for child in (node.values() if isinstance(node, dict) else node):
                if isinstance(child, (dict, list)):
                    tables.append(child)
                    stack.append(child)
        node = draw(st.sampled_from(tables))
        action = draw(st.sampled_from(["set", "delete", "add"]))
        if isinstance(node, dict):
            if action == "delete" and node:
                del node[draw(st.sampled_from(sorted(node)))]
            elif action == "set" and node:
                node[draw(st.sampled_from(sorted(node)))] = draw(values)
            else:
                node[draw(st.sampled_from(KEYS))] = draw(values)
        elif node:
            index = draw(st.integers(0, len(node) - 1))
            if action == "delete":
                del node[index]
            else:
                node[index] = draw(values)
    return doc


def to_toml(doc: dict) -> str:
    """A tiny TOML writer: every table inline, every key quoted (enough for any document)."""
    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, int):
            return str(v)
        if isinstance(v, float):
            if math.isnan(v):
                return "nan"
            if math.isinf(v):
                return "inf" if v > 0 else "-inf"
            return repr(v)
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return "{" + ", ".join(f"{json.dumps(k)} = {value(x)}" for k, x in v.items()) + "}"
    return "".join(f"{json.dumps(k)} = {value(v)}\n" for k, v in doc.items())


def _clean(load):
    try:
        m = load()
    except UserError as err:
        text = str(err)
        assert text and "\n" not in text
        return
    assert isinstance(m, missions.Mission)
    assert math.isfinite(m.duration) and m.duration > 0
    r = m.trajectory.sample(m.duration / 2)
    assert all(math.isfinite(v) for v in (r.x, r.y, r.vx, r.vy, r.ax, r.ay))


@SETTINGS
@given(mutated(VALID_TOML))
def test_mutated_toml_missions_load_or_fail_cleanly(doc):
    _clean(lambda: missions.loads(to_toml(doc), "<fuzz>"))


@SETTINGS
@given(st.dictionaries(st.sampled_from(KEYS), values, max_size=6))
def test_random_toml_tables_load_or_fail_cleanly(doc):
    _clean(lambda: missions.loads(to_toml(doc), "<fuzz>"))


@SETTINGS
@given(st.text(max_size=200))
def test_random_text_loads_or_fails_cleanly(text):
    _clean(lambda: missions.loads(text, "<fuzz>"))


def _item(lat, lon, command=16):
    return {"type": "SimpleItem", "command": command, "frame": 3, "autoContinue": True,
            "params": [0, 0, 0, None, lat, lon, 10]}


VALID_PLANS = [
    {"fileType": "Plan", "version": 1,
     "mission": {"cruiseSpeed": 2.0, "plannedHomePosition": [-35.363261, 149.16523, 584],
                 "items": [_item(-35.3630, 149.16523), _item(-35.3630, 149.1655),
                           _item(0, 0, command=20)], "version": 2}},
    {"fileType": "Plan", "version": 1,
     "mission": {"plannedHomePosition": [47.39774, 8.545594, 488],
                 "items": [{"type": "SimpleItem", "command": 178, "frame": 2,
                            "params": [1, 1.5, -1, 0, 0, 0, 0]},
                           _item(47.3980, 8.5456), _item(47.3981, 8.5459)]}},
]


def _load_plan_text(text: str):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.plan"
        path.write_text(text)
        return missions.load(path)


@SETTINGS
@given(mutated(VALID_PLANS))
def test_mutated_plans_load_or_fail_cleanly(doc):
    _clean(lambda: _load_plan_text(json.dumps(doc)))


@SETTINGS
@given(values)
def test_random_json_plans_load_or_fail_cleanly(doc):
    _clean(lambda: _load_plan_text(json.dumps(doc)))


def test_the_fuzzed_bases_are_valid():
    """The mutations start from documents that load (else the fuzzing proves little)."""
    for doc in VALID_TOML:
        assert isinstance(missions.loads(to_toml(doc)), missions.Mission)
    for doc in VALID_PLANS:
        assert isinstance(_load_plan_text(json.dumps(doc)), missions.Mission)
