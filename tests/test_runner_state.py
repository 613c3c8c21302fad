"""The live loop's state is declared in one place: ``Runner.__init__`` makes every attribute, in
a few named pieces (companion/live/loop_state.py: Heard, MissionClock, Engagement, ModeRequest,
Stopping, Timers, Counters), and every piece of state is read somewhere (no write-only flag).
Read with ``ast``: a method that invents an attribute, or a field nobody reads, fails here."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

from companion.live import loop_state, runner

SOURCE = Path(runner.__file__).read_text()
TREE = ast.parse(SOURCE)
PIECES = (loop_state.Heard, loop_state.MissionClock, loop_state.Engagement, loop_state.ModeRequest,
          loop_state.Stopping, loop_state.Timers, loop_state.Counters)


def _runner_class() -> ast.ClassDef:
    return next(n for n in TREE.body if isinstance(n, ast.ClassDef) and n.name == "Runner")


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
    cls = _runner_class()
    methods = [n for n in cls.body if isinstance(n, ast.FunctionDef)]
    init = next(m for m in methods if m.name == "__init__")
    made = {name for _, name in _self_targets(init)}
    own = {m.name for m in methods}
    late = [f"runner.py:{line}: {m.name} sets self.{name}, which __init__ does not make"
            for m in methods if m.name != "__init__"
            for line, name in _self_targets(m) if name not in made and name not in own]
    assert not late, "\n".join(late)
    assert len(made) <= 25, f"Runner.__init__ makes {len(made)} attributes: group them"


def test_every_piece_of_state_is_read():
    reads = {n.attr for n in ast.walk(TREE)
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
