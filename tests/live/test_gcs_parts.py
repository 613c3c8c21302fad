"""The pure parts of the ground-station work: what each event says (and how loud, within 50
characters), the values a GCS plots, a .plan written from mission items and read back, and how a
hand-over segment is found in a mission (and which missions are refused, naming the item)."""

from __future__ import annotations

import json
import math

import pytest

from companion.errors import ExitCode, UserError
from companion.live import events as ev
from companion.live import gcs
from companion.live.events import StatusEvent
from companion.live.handover import segments
from companion.mav import mission_transfer as mt
from companion.mission import plan_import


@pytest.mark.parametrize("event, severity, text", [
    (StatusEvent(ev.TRACKING, "circle"), gcs.NOTICE, "PZC: tracking: circle"),
    (StatusEvent(ev.FAILSAFE, "telemetry stale: no valid sample for 0.51 s"), gcs.CRITICAL,
     "PZC: FAILSAFE: telemetry stale: no valid sample..."),
    (StatusEvent(ev.PILOT_OVERRIDE, "mode changed to HOLD"), gcs.WARNING,
     "PZC: pilot took over: mode changed to HOLD"),
    (StatusEvent(ev.STOPPED, "mission_done", detail={"exit_code": ExitCode.OK}), gcs.NOTICE,
     "PZC: stopped: mission_done"),
    (StatusEvent(ev.STOPPED, "'m' starts 40 m away", detail={"exit_code": 2}), gcs.ERROR,
     "PZC: refused: 'm' starts 40 m away"),
    (StatusEvent(ev.STOPPED, "failsafe: telemetry lost", detail={"exit_code": 3}), gcs.CRITICAL,
     "PZC: stopped: failsafe: telemetry lost"),
])
def test_each_event_has_its_text_and_severity(event, severity, text):
    assert gcs.statustext(event) == (severity, text)
    assert len(text) <= gcs.TEXT_MAX


def test_texts_are_printable_ascii_within_50_characters():
    said = gcs.fit("é\x00" + "x" * 80)
    assert len(said) == 50 and said.endswith("...") and said.startswith("??")
    assert gcs.statustext(StatusEvent("no such kind")) is None


def test_the_values_a_gcs_plots():
    got = dict(gcs.values({"state": "paused", "mission_time": 5.0, "duration": 20.0}, 0.25))
    assert got == {"pzc_err": 0.25, "pzc_state": 4.0, "pzc_prog": 0.25, "pzc_mt": 5.0}
    assert all(len(name) <= 10 for name in gcs.VALUE_NAMES)
    assert dict(gcs.values({"state": "waiting", "duration": 0.0}, 0.0))["pzc_prog"] == 0.0


def _items():
    return [mt.item(0, 16, 0, (0, 0, 0, 0), -353632620, 1491652370, 584.0),
            mt.item(1, 178, 2, (1.0, 2.5, -1.0, math.nan), 0, 0, 0.0),
            mt.waypoint(2, -35.3631, 149.1653, 2.0),
            mt.waypoint(3, -35.36305, 149.16545)]


def test_a_plan_from_items_reads_back_the_same_items_and_imports(tmp_path):
    items = _items()
    loader = mt.mavwp.MAVWPLoader()
    for it in items:
        loader.add(it)
    plan = mt.to_plan(loader, home_item=True)
    assert plan["mission"]["plannedHomePosition"] == [-35.363262, 149.165237, 584.0]
    assert plan["mission"]["items"][0]["params"][3] is None          # NaN as QGC writes it
    assert mt.same_items(mt.plan_items(plan, home_item=True), items) == []
    path = tmp_path / "pulled.plan"
    path.write_text(json.dumps(plan))
    imported = plan_import.read(path)
    assert imported.waypoint_count == 2 and imported.speed == 2.5   # its DO_CHANGE_SPEED
    changed = mt.plan_items(plan, home_item=True)
    changed[2].x += 1
    assert mt.same_items(changed, items) == [f"item 2: x {items[2].x + 1} != {items[2].x}"]


def _mission(*rows):
    out = []
    for cmd, p1, p2, lat, lon in rows:
        out.append(mt.item(len(out), cmd, 3 if cmd == 16 else 2, (p1, p2, 0, 0),
                           int(lat * 1e7), int(lon * 1e7), 0.0))
    return out


HOME = (16, 0, 0, -35.0, 149.0)
WP = (16, 0, 0, -35.0001, 149.0001)
ON, OFF = (92, 1, 0, 0, 0), (92, 0, 0, 0, 0)


def test_a_segment_is_the_waypoints_between_an_enable_and_a_disable():
    found = segments(_mission(HOME, WP, (178, 1, 1.5, 0, 0), ON, WP, WP, OFF, WP, ON, WP, OFF))
    assert sorted(found) == [3, 8]
    first, second = found[3], found[8]
    assert (first.resume_seq, len(first.points), first.speed) == (6, 2, 1.5)
    assert (second.resume_seq, len(second.points)) == (10, 1)
    assert first.points[0] == pytest.approx((-35.0001, 149.0001))


@pytest.mark.parametrize("rows, words", [
    ((HOME, ON, WP), "item 1: NAV_GUIDED_ENABLE 1 is never closed"),
    ((HOME, ON, OFF), "mission items 1..2: a hand-over without NAV_WAYPOINT"),
    ((HOME, ON, WP, ON, WP, OFF), "mission item 3: NAV_GUIDED_ENABLE 1 inside"),
    ((HOME, (92, 1, 0, -35.0, 149.0), WP, OFF), "mission item 1: NAV_GUIDED_ENABLE with a "
                                                 "location"),
])
def test_a_malformed_segment_is_refused_naming_the_item(rows, words):
    with pytest.raises(UserError, match=words):
        segments(_mission(*rows))


class _Mav:
    def __init__(self):
        self.acks, self.texts = [], []

    def command_ack_send(self, command, result, *rest):
        self.acks.append((command, result, rest[-2:]))

    def statustext_send(self, severity, text):
        self.texts.append(text.decode())


class _Cmd:
    def __init__(self, param1, target=(1, 191), command=193):
        self.command, self.param1 = command, param1
        self.target_system, self.target_component = target

    def get_srcSystem(self):
        return 255

    def get_srcComponent(self):
        return 190


@pytest.mark.parametrize("param1, verb, result", [
    (0.0, "pause", gcs.MAV_RESULT_ACCEPTED), (1.0, "resume", gcs.MAV_RESULT_ACCEPTED),
    (math.nan, None, gcs.MAV_RESULT_DENIED), (2.0, None, gcs.MAV_RESULT_DENIED)])
def test_do_pause_continue_becomes_the_loops_request_and_is_acked(param1, verb, result):
    mav = _Mav()
    cmds = gcs.GcsCommands(mav, lambda: 1, 191, gcs.GcsReporter(mav))
    asked = []

    def handle(req):
        asked.append(req.verb)
        req.reply(True, "ok")
    assert cmds.on_command(_Cmd(param1), handle)
    assert asked == ([verb] if verb else [])
    assert mav.acks == [(193, result, (255, 190))]
    assert (mav.texts == []) == (verb is not None)


def test_commands_for_the_autopilot_are_left_alone():
    cmds = gcs.GcsCommands(_Mav(), lambda: 1, 191)
    assert not cmds.on_command(_Cmd(0.0, target=(1, 1)), lambda req: None)
    assert not cmds.on_command(_Cmd(0.0, command=176), lambda req: None)
    assert cmds.on_command(_Cmd(0.0, target=(0, 0)), lambda req: req.reply(False, "no"))
