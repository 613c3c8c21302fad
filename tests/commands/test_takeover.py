"""A pilot takes over (the plant flips to HOLD mid-mission): the companion sends nothing more,
not even a zero setpoint or a mode request, and says so. And a vehicle whose heartbeat stops
for 3 s is stopped (zero setpoint, HOLD) and only re-engaged once heartbeats are back.
Real processes over loopback UDP."""

from __future__ import annotations

import signal
import time

import pytest

from sitl_plant.testing import PlantProcess, free_udp_port
from testbed.fake_vehicle import FakeVehicle, is_mode_command, is_zero
from testbed.missions import ellipse_mission
from testbed.process import Companion
from testbed.udp_proxy import Proxy

HOLD, GUIDED = 4, 15
# Vehicle seconds: the companion's setup (rate negotiation, parameters, the estimator's first
# report) engages GUIDED at about 4-5 s of plant time even on a quiet machine, so a takeover at
# 5 s raced the engagement (CI once saw it land first: HOLD, then the companion's own GUIDED).
TAKEOVER_S = 15.0


@pytest.mark.parametrize("how", ["lockstep --takeover-at", "paced SIGUSR1"])
def test_pilot_takeover_stops_the_companion_within_one_cycle(tmp_path, how):
    mission = ellipse_mission(tmp_path / "m.toml", 30.0)
    plant_args = (["--lockstep", "--takeover-at", str(TAKEOVER_S)] if how.startswith("lockstep")
                  else ["--speedup", "2"])
    with Proxy() as proxy, \
            Companion(proxy.companion_port, "--arm", "--no-zenoh", "--json", "--mission",
                      str(mission),
                      "--log-dir", str(tmp_path)) as comp:
        comp.wait_bound(proxy.companion_port)   # the plant's clock starts with a listener
        with PlantProcess(*plant_args, "--d-cen", "0.3", port=proxy.plant_port) as plant:
            if how.startswith("paced"):
                comp.wait_until(lambda: sum(1 for s in proxy.companion_sent(
                    "SET_POSITION_TARGET_LOCAL_NED") if not is_zero(s.msg)) >= 100, 20.0,
                    "100 tracking setpoints")
                plant.proc.send_signal(signal.SIGUSR1)
            code = comp.wait(30.0)
            r = comp.result()
            time.sleep(0.3)
    assert code == 4, comp.stderr
    assert r["reason"] == "pilot_override: mode changed to HOLD by someone else"
    assert "pilot took over" in comp.stderr
    # The takeover is the HOLD after the last GUIDED heartbeat: on a loaded machine a stalled
    # plant can failsafe the run into a HOLD the companion asked for, and back to GUIDED,
    # before it (a make test once saw 40 setpoints "after" such an earlier HOLD).
    beats = proxy.plant_sent("HEARTBEAT")
    guided = [i for i, s in enumerate(beats) if s.msg.custom_mode == GUIDED]
    assert guided, "the plant never reported GUIDED"
    hold_hb = [s for s in beats[guided[-1] + 1:] if s.msg.custom_mode == HOLD]
    assert hold_hb, "the plant never reported HOLD after GUIDED"
    t_hold = hold_hb[0].wall
    before = [s.msg.time_boot_ms for s in proxy.plant_sent("LOCAL_POSITION_NED")
              if s.wall < t_hold]
    # No mode request, and not one setpoint for a sample sent after the takeover. (A setpoint
    # for the last sample before it may pass the proxy just after the HOLD heartbeat did: it
    # was on its way while the heartbeat was, seen once in a make test beside a SITL suite.)
    after = [s for s in proxy.from_companion if s.wall > t_hold
             and (s.msg.get_type() == "COMMAND_LONG"
                  or (s.msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
                      and s.msg.time_boot_ms > before[-1]))]
    assert after == [], ([s.msg.get_type() for s in after], r.get("failsafes"))
    assert len([s for s in proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED", after=t_hold)
                ]) <= 1
    # the last setpoint answered the last sample sent before the takeover: within one cycle
    last_sp = proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")[-1]
    assert last_sp.msg.time_boot_ms == before[-1], (last_sp.msg.time_boot_ms, before[-3:])
    assert not is_zero(last_sp.msg)                  # it was tracking, and then it was silent
    if how.startswith("lockstep"):
        assert before[-1] == TAKEOVER_S * 1000
    csv = next(tmp_path.glob("*.csv")).read_text()
    assert "pilot_override: mode changed to HOLD by someone else" in csv
    print(f"\ntakeover ({how}): last setpoint answered sample {last_sp.msg.time_boot_ms} ms, "
          f"sent {1e3 * (t_hold - last_sp.wall):.2f} ms before the HOLD heartbeat reached the "
          f"proxy; 0 setpoints or commands after it; companion exit {code}")


def test_the_autopilots_battery_failsafe_is_named_though_its_heartbeat_comes_first(tmp_path):
    """ArduPilot's battery failsafe in the order SITL sends it (the plant's --battery-low-at):
    the HOLD heartbeat, then "Battery 1 is low ...", then SYS_STATUS with the battery bit
    unhealthy. The companion ends naming the battery failsafe (exit 5), not a pilot, and sends
    nothing after the HOLD heartbeat (issue 44: it said "pilot_override")."""
    mission = ellipse_mission(tmp_path / "m.toml", 30.0)
    with Proxy() as proxy, \
            Companion(proxy.companion_port, "--arm", "--no-zenoh", "--json", "--mission",
                      str(mission), "--log-dir", str(tmp_path)) as comp:
        comp.wait_bound(proxy.companion_port)
        with PlantProcess("--lockstep", "--battery-low-at", str(TAKEOVER_S), "--d-cen", "0.3",
                          port=proxy.plant_port):
            code = comp.wait(30.0)
            r = comp.result()
    assert code == 5 and r["stop_cause"] == "autopilot_failsafe", comp.stderr
    assert r["reason"].startswith('autopilot_failsafe: the autopilot\'s battery failsafe '
                                  '("Battery 1 is low'), r
    assert r["reason"].endswith("switched to HOLD"), r
    assert "pilot_override" not in r["reason"] and "pilot took over" not in comp.stderr
    order = [s.msg.get_type() for s in proxy.from_plant
             if (s.msg.get_type() == "HEARTBEAT" and s.msg.custom_mode == HOLD)
             or (s.msg.get_type() == "STATUSTEXT" and "Battery" in s.msg.text)]
    assert order[:2] == ["HEARTBEAT", "STATUSTEXT"], order     # the heartbeat first, as SITL
    t_hold = next(s.wall for s in proxy.plant_sent("HEARTBEAT") if s.msg.custom_mode == HOLD
                  and s.wall > proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")[0].wall)
    after = [s.msg.get_type() for s in proxy.from_companion if s.wall > t_hold
             and s.msg.get_type() in ("COMMAND_LONG", "SET_POSITION_TARGET_LOCAL_NED")]
    assert len(after) <= 1 and "COMMAND_LONG" not in after, after   # (one already on its way)


CRITICAL = 5    # MAV_STATE_CRITICAL: the autopilot's failsafe


@pytest.mark.parametrize("who", ["pilot", "autopilot"])
def test_a_mode_chosen_by_someone_else_before_the_companion_engaged_is_not_taken(tmp_path, who):
    """While the companion sets up (telemetry flowing, the estimator's first report awaited for
    a second), the pilot flips the mode switch to HOLD, or the autopilot's EKF failsafe does.
    The vehicle was never the companion's: it asks for no mode, does not arm, sends no tracking
    setpoint, and ends saying whose choice it was (exit 4, or 5 for the failsafe)."""
    mission = ellipse_mission(tmp_path / "m.toml", 5.0)
    at: list[int] = []       # the tick of the switch: once the loop answers (its stop setpoints)

    def script(k, ms):
        # the setup's rate negotiation reads ticks too, so count from the loop's first answer;
        # 4 ticks on is 0.1 vehicle s, well inside the second it waits before asking a mode
        if not at and fake.setpoints:
            at.append(k + 4)
        if at and k == at[0]:
            return ({"mode": HOLD} if who == "pilot" else
                    {"mode": HOLD, "status": CRITICAL, "text": "EKF failsafe"})
        return None

    port = free_udp_port()
    fake = FakeVehicle(port, script=script)     # bound before its thread runs the script
    with Companion(port, "--arm", "--no-zenoh", "--json", "--mission", str(mission),
                   "--log-dir", str(tmp_path)) as comp, fake:
        code = comp.wait(30.0)
        r = comp.result()
    assert not [c.command for c in fake.commands if c.command in (176, 400)], comp.stderr
    assert fake.setpoints and all(is_zero(sp) for sp in fake.setpoints)
    if who == "pilot":
        assert code == 4, comp.stderr
        assert r["reason"] == ("pilot_override: mode changed to HOLD by someone else before "
                               "the companion engaged"), r
        assert "pilot took over" in comp.stderr
    else:
        assert code == 5, comp.stderr
        assert r["reason"].startswith("autopilot_failsafe: the autopilot's ekf failsafe"), r
        assert r["reason"].endswith("switched to HOLD before the companion engaged"), r
    # and nothing after the vehicle said so: not one setpoint for a later sample
    t_mode = fake.sent_ms[at[0]][0]
    assert not [sp for sp in fake.setpoints if sp.time_boot_ms > t_mode], comp.stderr


@pytest.mark.parametrize("flags", [("--start-on-guided",), ("--arm", "--estimate-wait", "60")])
def test_a_stop_before_the_companion_asked_anything_leaves_the_vehicle_as_it_was(tmp_path, flags):
    """Ctrl-C / SIGTERM while the companion waits for the pilot to select GUIDED
    (--start-on-guided), or for a healthy estimate before its first mode request: the vehicle
    is in the pilot's MANUAL and was never asked anything. Stopping sends no HOLD (which would
    stop the rover under the pilot), no arming: the run ends, exit 0, saying it left the vehicle
    as it was."""
    mission = ellipse_mission(tmp_path / "m.toml", 5.0)
    booting = 0x0          # EKF_STATUS_REPORT flags with no position: the estimate never healthy

    def script(k, ms):
        return {"ekf": booting} if "--estimate-wait" in flags and k % 8 == 0 else None

    port = free_udp_port()
    with Companion(port, *flags, "--no-zenoh", "--json", "--no-log", "--mission",
                   str(mission)) as comp, FakeVehicle(port, script=script) as fake:
        comp.wait_for_stderr("waiting for the pilot" if "--start-on-guided" in flags
                             else "waiting for a healthy position estimate", 30.0)
        comp.proc.send_signal(signal.SIGTERM)
        code = comp.wait(20.0)
        r = comp.result()
    assert code == 0 and (r["reason"], r["stop_cause"]) == ("SIGTERM", "ok"), (r, comp.stderr)
    assert not [c.command for c in fake.commands if c.command in (176, 400)], comp.stderr
    assert fake.mode == 0 and not fake.armed            # MANUAL, as the pilot left it
    assert all(is_zero(sp) for sp in fake.setpoints)
    assert "nothing had been asked of the vehicle: left as it was, in MANUAL" in comp.stderr


def test_an_autopilot_leaving_its_boot_mode_is_nobodys_choice(tmp_path):
    """ArduPilot reports INITIALISING while it starts, then its INITIAL_MODE on its own: a
    companion started with it engages as usual once the vehicle has settled."""
    mission = ellipse_mission(tmp_path / "m.toml", 3.0)
    at: list[int] = []

    def script(k, ms):
        if not at and fake.setpoints:
            at.append(k + 4)
        return {"mode": 0} if at and k == at[0] else None        # INITIALISING -> MANUAL

    port = free_udp_port()
    fake = FakeVehicle(port, script=script)
    fake.mode = 16                                              # INITIALISING
    with Companion(port, "--arm", "--no-zenoh", "--json", "--mission", str(mission),
                   "--log-dir", str(tmp_path)) as comp, fake:
        code = comp.wait(30.0)
        r = comp.result()
    assert code == 0 and r["reason"] == "mission_done", comp.stderr
    assert "mode INITIALISING" in comp.stderr
    assert [c for c in fake.commands if is_mode_command(c, GUIDED)], comp.stderr


class QuietVehicle(FakeVehicle):
    """The scripted vehicle, with heartbeats that can be switched off, and wall times of what
    the companion sent it."""

    silent = False

    def _heartbeat(self) -> None:
        if not self.silent:
            self.last_heartbeat = time.monotonic()
            super()._heartbeat()

    def _handle(self, msg) -> bool:
        self.stamped = getattr(self, "stamped", [])
        self.stamped.append((time.monotonic(), msg))
        return super()._handle(msg)


def test_heartbeat_lost_for_3_s_stops_the_rover_then_holds_and_resumes(tmp_path):
    # --stale-timeout 2.5: what is measured is the heartbeat's failsafe; on a loaded machine
    # the scripted vehicle's thread can stall its telemetry for over the default 0.5 s (a fresh
    # clone's make test beside a SITL did: "filter and integrators reset", then the stale
    # failsafe's HOLD 1.5 s after the last heartbeat, read as this one's reaction)
    mission = ellipse_mission(tmp_path / "m.toml", 3600.0)
    port = free_udp_port()
    with Companion(port, "--arm", "--no-zenoh", "--json", "--mission", str(mission), "--log-dir",
                   str(tmp_path), "--stale-timeout", "2.5") as comp, QuietVehicle(port) as fake:
        deadline = time.monotonic() + 20
        while sum(1 for sp in fake.setpoints if not is_zero(sp)) < 40:
            assert time.monotonic() < deadline, comp.stderr
            time.sleep(0.02)
        fake.silent = True
        time.sleep(0.05)
        t_last = fake.last_heartbeat
        time.sleep(4.5)
        fake.silent = False
        t_resumed = time.monotonic()
        deadline = t_resumed + 10
        while not any(w > t_resumed and m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
                      and not is_zero(m) for w, m in list(fake.stamped)):
            assert time.monotonic() < deadline, comp.stderr
            time.sleep(0.05)
        comp.proc.send_signal(signal.SIGTERM)
        assert comp.wait(20.0) == 0, comp.stderr
        r = comp.result()
    stamped = [(w, m) for w, m in fake.stamped if w > t_last]
    holds = [w for w, m in stamped if m.get_type() == "COMMAND_LONG" and is_mode_command(m, HOLD)]
    assert holds, "no HOLD after the heartbeat stopped"
    reaction = holds[0] - t_last
    assert 3.0 <= reaction <= 3.8, (reaction, comp.stderr)
    # from the failsafe until heartbeats came back: only zero setpoints
    t_back = t_last + 4.55
    sps = [(w, m) for w, m in stamped if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
    during = [m for w, m in sps if holds[0] <= w < t_back]
    assert during and all(is_zero(m) for m in during)
    assert is_zero([m for w, m in sps if w < holds[0]][-1])     # the stop came before HOLD
    guided = [w for w, m in stamped if m.get_type() == "COMMAND_LONG"
              and is_mode_command(m, GUIDED) and w > holds[0]]
    assert guided and guided[0] >= t_back - 0.05           # re-engaged once the link was back
    assert r["reason"] == "SIGTERM" and r["failsafes"] == 1
    assert "heartbeat lost" in comp.stderr
    print(f"\nheartbeat lost: HOLD requested {reaction:.2f} s after the last heartbeat; "
          f"{len(during)} zero setpoints meanwhile; GUIDED again {guided[0] - t_back:+.2f} s "
          f"after heartbeats resumed")
