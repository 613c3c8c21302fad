"""What the view keeps of each rover (companion/view/fleet.py), from real bus payloads: paths
grow and stay bounded, failsafes show until tracking resumes, a silent rover is stale, and what
is not ours is counted, not drawn."""

from __future__ import annotations

from companion.bus import codec
from companion.live.events import LoopRecord, StatusEvent
from companion.view import fleet as fl
from companion.view.draw import label, table


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def _state(vid: str, seq: int, x: float, y: float) -> bytes:
    rec = LoopRecord(seq * 0.025, seq * 0.025, x, y, 0.1, x, y, 0.1, x + 0.1, y, 0.1, 0.0,
                     1.0, 0.0, 1.2, 0.3, "GUIDED", True)
    return codec.encode(codec.state_payload(vid, seq, 1, rec, 1.7e9 + seq * 0.025))


def _status(vid: str, kind: str, reason: str = "") -> bytes:
    return codec.encode(codec.status_payload(vid, 1, StatusEvent(kind, reason), 1.7e9))


def test_paths_states_failsafes_and_staleness():
    clock = Clock()
    f = fl.Fleet(stale_after=2.0, clock=clock)
    f.add("rover/r1/status", _status("r1", "connected"))
    for i in range(10):
        f.add("rover/r1/state", _state("r1", i, i * 0.1, 0.0))
    (r,) = f.take()
    assert r.phase == "tracking" and not r.stale and len(r.driven) == 10
    assert r.driven[-1] == (0.9, 0.0) and r.reference[-1][0] == 0.9 + 0.1
    assert len(r.series) == 10 and r.series[0][2] == 1.2
    assert [e["kind"] for e in r.events] == ["connected"]
    f.add("rover/r1/status", _status("r1", "failsafe", "telemetry lost"))
    (r,) = f.take()
    assert r.failsafe == "telemetry lost" and label(r) == "r1 FAILSAFE: telemetry lost"
    assert r.events and f.take()[0].events == []        # events are handed over once
    f.add("rover/r1/status", _status("r1", "resumed"))
    assert f.take()[0].failsafe == ""
    clock.t += 2.5
    (r,) = f.take()
    assert r.stale and label(r).startswith("r1 STALE") and "**STALE**" in table([r])


def test_paths_are_thinned_never_cut():
    f = fl.Fleet(clock=Clock())
    n = fl.MAX_POINTS * 3
    for i in range(n):
        f.add("rover/r2/state", _state("r2", i, float(i), 0.0))
    (r,) = f.take()
    assert len(r.driven) <= fl.MAX_POINTS + 1
    assert r.driven[0] == (0.0, 0.0) and r.driven[-1][0] > n * 0.9   # start and end both kept


def test_what_is_not_ours_is_counted():
    f = fl.Fleet(clock=Clock())
    f.add("rover/r3/state", b"not json at all")
    f.add("rover/r3/state", _status("r3", "tracking"))          # a status on the state key
    f.add("somewhere/else", b"{}")
    f.add("rover/r3/state", _state("r3", 1, 0.0, 0.0))
    assert f.bad == 1 and f.rovers["r3"].bad == 2 and f.rovers["r3"].state_msgs == 1
