"""The live loop's state is declared in one place: ``LoopCore.__init__`` (companion/live/runner/
core.py) makes every attribute, in a few named pieces (companion/live/loop_state.py: Heard,
MissionClock, Engagement, ModeRequest, Stopping, Timers, Counters), the parts built on it
(ending, engaging, failsafes, requests, loop) make none, and every piece of state is read
somewhere (no write-only flag). Read with ``ast``: a method in any part that invents an
attribute, or a field nobody reads, fails here."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

from companion.live import loop_state, runner

PARTS = sorted(Path(runner.__file__).parent.glob("*.py"))
SOURCE = "\n".join(path.read_text() for path in PARTS)
TREES = {path.name: ast.parse(path.read_text()) for path in PARTS}
PIECES = (loop_state.Heard, loop_state.MissionClock, loop_state.Engagement, loop_state.ModeRequest,
          loop_state.Stopping, loop_state.Timers, loop_state.Counters)


def _methods() -> list[tuple[str, ast.FunctionDef]]:
    """(file, method) of every method of every class in the runner's modules."""
    return [(name, m) for name, tree in TREES.items() for cls in tree.body
            if isinstance(cls, ast.ClassDef) for m in cls.body if isinstance(m, ast.FunctionDef)]


def _self_targets(fn: ast.FunctionDef) -> list[tuple[int, str]]:
    """(line, name) of every ``self.name = ...`` (plain, augmented, annotated, unpacked)."""
    out = []
    for node in ast.walk(fn):
        targets = (node.targets if isinstance(node, ast.Assign)
                   else [node.target] if isinstance(node, (ast.AugAssign, ast.AnnAssign)) else [])
        stack = list(targets)
        while stack:
            t = stack.pop()
            if isinstance(t, (ast.Tuple, ast.List)):
                stack += t.elts
            elif (isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name)
                  and t.value.id == "self"):
                out.append((t.lineno, t.attr))
    return out


def test_every_runner_attribute_is_made_in_init():
    methods = _methods()
    inits = [(file, m) for file, m in methods if m.name == "__init__"]
    assert [file for file, _ in inits] == ["core.py"], f"__init__ in {inits}: only LoopCore's"
    made = {name for _, name in _self_targets(inits[0][1])}
    own = {m.name for _, m in methods}
    late = [f"{file}:{line}: {m.name} sets self.{name}, which __init__ does not make"
            for file, m in methods if m.name != "__init__"
            for line, name in _self_targets(m) if name not in made and name not in own]
    assert not late, "\n".join(late)
    assert len(made) <= 25, f"LoopCore.__init__ makes {len(made)} attributes: group them"


def test_each_method_has_one_home():
    """A method defined in two parts would shadow one by the other, silently, by the MRO."""
    homes: dict[str, list[str]] = {}
    for file, m in _methods():
        homes.setdefault(m.name, []).append(file)
    twice = {name: files for name, files in homes.items() if len(files) > 1}
    assert not twice, twice


def test_every_piece_of_state_is_read():
    reads = {n.attr for tree in TREES.values() for n in ast.walk(tree)
             if isinstance(n, ast.Attribute) and isinstance(n.ctx, ast.Load)}
    unread = [f"{piece.__name__}.{f.name}" for piece in PIECES
              for f in dataclasses.fields(piece) if f.name not in reads]
    assert not unread, f"written, never read: {unread}"
    assert "_mode_acked" not in SOURCE


def test_a_fresh_runner_has_all_its_state(monkeypatch):
    """No attribute appears later (getattr fallbacks): a Runner just made has every piece."""
    from types import SimpleNamespace

    from companion.core.limits import Limits
    from companion.live.runner import Runner, RunnerConfig
    from companion.profiles import px4
    link = SimpleNamespace(vehicle=SimpleNamespace(sysid=1, compid=1, profile=px4.PROFILE),
                           mode="HOLD")      # as the setup left it: the mode it found
    mission = SimpleNamespace(duration=10.0, name="m")
    r = Runner(link, object(), mission, RunnerConfig(autostart=False), Limits(1.0, 1.0))
    assert r.engagement.start_mode == "HOLD"
    assert (r.track_mode, r.hold_mode) == ("OFFBOARD", "LOITER")
    assert r.engagement.after is loop_state.State.READY and r.stopping.wants_hold is False
    assert (r.mission_time, r.failsafes, r.sink_errors, r.tracker_resets) == (0.0, 0, 0, 0)
    for piece in PIECES:
        assert sum(isinstance(v, piece) for v in vars(r).values()) == 1, piece.__name__


# The live modules beneath the loop (its package docstring); session, policy, the ground
# station's and the setup's modules build on the loop, never the other way.
BENEATH = {"link", "telemetry", "health", "loop_state", "stats", "events", "config", "handover",
           "gnss_watch", "gnss_jump"}


def test_the_loop_imports_only_what_lies_beneath_it():
    # tests/project/test_layers.py's reader, by its path: that folder is on sys.path only
    # once pytest has collected a module there (this file alone failed: no test_layers)
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        "test_layers_reader", Path(__file__).resolve().parents[1] / "project" / "test_layers.py")
    assert spec is not None and spec.loader is not None
    layers = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(layers)
    imports = layers.imports
    bad = []
    for path in PARTS:
        for line, module in imports(path, "companion.live.runner"):
            parts = module.split(".")
            if parts[:2] == ["companion", "live"] and len(parts) > 2 and parts[2] != "runner" \
                    and parts[2] not in BENEATH:
                bad.append(f"{path.name}:{line}: {module}")
    assert not bad, bad
