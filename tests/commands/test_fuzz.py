"""Fuzz: malformed MAVLink into the companion and into the plant, well over 100,000 frames.

In-process for volume (the real Link / pymavlink parser / TelemetryCheck / Runner, and the real
plant Link / PlantServer / Vehicle, with only the socket replaced by a list of datagrams), then
over real UDP into the two real processes flying a mission. Nothing may crash or hang, no
setpoint may answer bad data, and every setpoint must be finite and within the limits.
"""

from __future__ import annotations

import math
import random
import time
from collections import Counter, deque

from companion.core.limits import Limits
from companion.core.pzc import PZCTracker
from companion.live.link import Link, LinkConfig
from companion.live.runner import Runner, RunnerConfig
from companion.mission import paper_ellipse
from companion.profiles.setpoint import MAX_TARGET_RATE, MAX_TARGET_SPEED
from sitl_plant.config import PlantConfig
from sitl_plant.link import Link as PlantLink
from sitl_plant.server import PlantServer
from sitl_plant.testing import MASK_SPEED_TURN_RATE, PlantProcess, free_udp_port
from testbed.fuzz import Fuzzer, wild
from testbed.missions import ellipse_mission
from testbed.process import Companion
from testbed.safety import InjectingProxy, encoder, frame
from testbed.udp_proxy import _parser

LIMITS = Limits(max_speed=3.0, max_yaw_rate=2.0)
STEP_MS = 25
TOTALS: Counter = Counter()       # frames tried per target, reported at the end


class Wire:
    """Stands in for the socket under a pymavlink connection: ``recv`` hands out queued
    datagrams, ``write`` keeps what was sent."""

    def __init__(self, conn, refill=None):
        self.inbox: deque[bytes] = deque()
        self.sent = bytearray()
        self.refill = refill
        conn.recv = self.recv
        conn.write = self.write
        conn.select = lambda timeout: False

    def recv(self, n=None) -> bytes:
        if not self.inbox and self.refill is not None:
            self.refill()
        return self.inbox.popleft() if self.inbox else b""

    def write(self, buf) -> None:
        self.sent += buf


# --- the companion --------------------------------------------------------------------------
class FakeVehicleStream:
    """Good telemetry of a rover on a circle (ATTITUDE + LOCAL_POSITION_NED every 25 ms, a GUIDED
    armed heartbeat now and then) with ``per_tick`` malformed frames between ticks."""

    def __init__(self, wire: Wire, ticks: int, per_tick: int, seed: int):
        self.wire, self.ticks, self.per_tick = wire, ticks, per_tick
        self.mav = encoder(None, sysid=1, compid=1)
        self.k = 0
        self.ms = 10_000
        self.good_ms: set[int] = set()
        self.fuzz = Fuzzer(seed, self.bad)
        self.runner: Runner | None = None

    def heartbeat(self) -> bytes:
        return frame(self.mav, self.mav.heartbeat_encode(10, 3, 1 | 8 | 128, 15, 4))

    def bad(self, rng: random.Random, mav, plausible: bool):
        odd = self.ms + rng.choice((1, 7, 13, 24))          # never on the 25 ms grid
        if plausible:           # a stranger (other system / component) with sane values
            return rng.choice((
                lambda: mav.local_position_ned_encode(odd, 5.0, 5.0, 0, 1.0, 0, 0),
                lambda: mav.attitude_encode(odd, 0, 0, 0.5, 0, 0, 0.1),
                lambda: mav.heartbeat_encode(10, 3, 1 | 128, 4, 4)))()
        t = odd
        pos = [rng.uniform(-5, 5) for _ in range(4)]
        pos[rng.randrange(4)] = wild(rng)
        return rng.choice((
            lambda: mav.local_position_ned_encode(t, pos[0], pos[1], wild(rng), pos[2], pos[3],
                                                  wild(rng)),
            lambda: mav.attitude_encode(t, wild(rng), wild(rng), wild(rng), 0, 0,
                                        rng.uniform(-1, 1)),
            lambda: mav.attitude_encode(t, 0, 0, rng.uniform(-1, 1), 0, 0, wild(rng)),
            # a clock jump far ahead with sane values: refused until a second sample agrees
            lambda: mav.local_position_ned_encode(min(self.ms + rng.randint(2_000, 2**31),
                                                      2**32 - 1), 1.0, 1.0, 0, 0.5, 0, 0),
            lambda: mav.attitude_encode(min(self.ms + rng.randint(2_000, 2**31), 2**32 - 1),
                                        0, 0, 3.0, 0, 0, 0),
            lambda: mav.command_ack_encode(rng.randint(0, 65535), rng.randint(0, 255)),
            lambda: mav.statustext_encode(rng.randint(0, 255), rng.randbytes(50)),
            lambda: mav.heartbeat_encode(rng.randint(0, 40), rng.randint(0, 20), 1 | 8 | 128, 15,
                                         rng.randint(0, 255)),
        ))()

    def refill(self) -> None:
        if self.k >= self.ticks:
            if self.runner is not None:
                self.runner.request_stop("fuzz done")
            return
        inbox, mav, fuzz = self.wire.inbox, self.mav, self.fuzz
        self.ms += STEP_MS
        k, ms = self.k, self.ms
        t = ms / 1000.0
        x, y = 5.0 * math.sin(0.2 * t), 5.0 - 5.0 * math.cos(0.2 * t)
        yaw = math.remainder(0.2 * t, 2 * math.pi)
        if k % 40 == 0:
            inbox.append(fuzz.good(self.heartbeat()))
        inbox.append(fuzz.good(frame(mav, mav.attitude_encode(ms, 0, 0, yaw, 0, 0, 0.2))))
        inbox.append(fuzz.good(frame(mav, mav.local_position_ned_encode(
            ms, x, y, 0, math.cos(yaw), math.sin(yaw), 0))))
        self.good_ms.add(ms)
        for _ in range(self.per_tick):
            inbox.append(fuzz.frame())
        self.k += 1


def sent_setpoints(data: bytes) -> list:
    return [m for m in _parser().parse_buffer(bytes(data)) or []
            if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]


def test_fuzz_the_companion_in_process():
    link = Link(LinkConfig(url=f"udpin:127.0.0.1:{free_udp_port()}", heartbeat_timeout=2.0))
    wire = Wire(link.master)
    stream = FakeVehicleStream(wire, ticks=10_000, per_tick=6, seed=1)
    try:
        wire.inbox.append(stream.heartbeat())
        link.wait_vehicle()
        wire.refill = stream.refill
        mission = paper_ellipse(0.05, 1e6)
        runner = Runner(link, PZCTracker(limits=LIMITS), mission,
                        RunnerConfig(arm=True, hold_timeout=0.05, stale_timeout=2.0,
                                     period=STEP_MS / 1000), LIMITS)
        stream.runner = runner
        t0 = time.perf_counter()
        outcome = runner.run()
        wall = time.perf_counter() - t0
    finally:
        link.close()
    fuzzed = sum(stream.fuzz.counts.values())
    TOTALS["companion (in process)"] += fuzzed
    sps = sent_setpoints(wire.sent)
    answered_bad = [sp.time_boot_ms for sp in sps
                    if sp.time_boot_ms != 0 and sp.time_boot_ms not in stream.good_ms]
    invalid = [sp for sp in sps if not (
        all(math.isfinite(v) for v in (sp.vx, sp.vy, sp.yaw_rate))
        and abs(sp.vx) <= LIMITS.max_speed + 1e-6 and abs(sp.yaw_rate) <= LIMITS.max_yaw_rate + 1e-6
        and sp.vy == 0.0)]
    rej = runner.telemetry.rejected
    print(f"\ncompanion fuzz: {fuzzed} malformed frames {dict(stream.fuzz.counts)} in {wall:.1f} s;"
          f" {len(sps)} setpoints, {len(answered_bad)} answering bad data, {len(invalid)} invalid;"
          f" cycles {runner.stats.cycles}, refused {dict(rej)}, outcome {outcome.reason}")
    assert fuzzed >= 60_000 and set(stream.fuzz.counts) == set(
        ("random_bytes", "random_v2_header", "bit_flip", "truncated", "wrong_length",
         "wrong_ids", "replay", "bad_values"))
    assert outcome.reason == "fuzz done" and outcome.exit_code == 0
    assert answered_bad == [] and invalid == []
    # it kept flying through the storm: most good ticks were tracked
    assert runner.stats.cycles >= 0.6 * stream.ticks, runner.stats.cycles
    assert rej["not_finite"] > 500 and rej["out_of_range"] > 500 and rej["other_source"] > 500
    assert rej["time_jump"] > 100 and rej["time_backwards"] + rej["duplicate"] > 500
    assert wall < 45.0


# --- the plant ------------------------------------------------------------------------------
class PilotStream:
    """A ground station arming, switching to GUIDED and streaming (1 m/s, 0.2 rad/s) setpoints,
    with malformed frames between them."""

    def __init__(self, seed: int):
        self.mav = encoder(None, sysid=255, compid=190)
        self.fuzz = Fuzzer(seed, self.bad)

    def bad(self, rng: random.Random, mav, plausible: bool):
        target = rng.choice((2, 7, 200)) if plausible else 1
        w = lambda: wild(rng)   # noqa: E731
        return rng.choice((
            lambda: mav.set_position_target_local_ned_encode(
                0, target, 1, rng.choice((1, 7, 8, 9, 0, 255)), rng.randint(0, 65535),
                w(), w(), w(), w(), w(), w(), w(), w(), w(), w(), w()),
            lambda: mav.set_position_target_local_ned_encode(
                0, target, 1, 8, MASK_SPEED_TURN_RATE, 0, 0, 0, w(), 0, 0, 0, 0, 0, 0, 0.1),
            lambda: mav.set_position_target_local_ned_encode(
                0, target, 1, 8, MASK_SPEED_TURN_RATE, 0, 0, 0, 1.0, 0, 0, 0, 0, 0, 0, w()),
            lambda: mav.command_long_encode(target, 1, rng.choice((176, 400, 511, 512, 510, 0)),
                                            0, w(), w(), w(), w(), w(), w(), w()),
            lambda: mav.command_long_encode(target, 1, 176, 0, 1, rng.choice(
                (-1, 2, 9, 99, 255, 1e9, -1e9)), 0, 0, 0, 0, 0),
            lambda: mav.command_long_encode(target, 1, 400, 0, rng.choice((2.0, -1.0, 0.5, 1e9)),
                                            0, 0, 0, 0, 0, 0),
            lambda: mav.command_int_encode(target, 1, 0, rng.choice((176, 400, 511)), 0, 0,
                                           w(), w(), w(), w(), rng.randint(-2**31, 2**31 - 1),
                                           0, w()),
            lambda: mav.set_mode_encode(target, rng.randint(0, 255), rng.choice((2, 9, 99, 2**31))),
        ))()


def test_fuzz_the_plant_in_process():
    port = free_udp_port()
    config = PlantConfig(connect=f"udpout:127.0.0.1:{port}", loop_rate=100.0)
    link = PlantLink(config.connect, config.sysid, config.compid)
    wire = Wire(link.conn)
    server = PlantServer(config, link)
    pilot = PilotStream(seed=2)
    mav = pilot.mav
    params = config.vehicle.params
    # the paper's plant has no speed limit of its own (inf): the targets' plausibility caps it
    max_speed = min(params.max_speed, MAX_TARGET_SPEED)
    max_rate = min(params.max_yaw_rate, MAX_TARGET_RATE)
    good = lambda m: pilot.fuzz.good(frame(mav, m))   # noqa: E731
    wire.inbox += [good(mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)),
                   good(mav.command_long_encode(1, 1, 176, 0, 1, 15, 0, 0, 0, 0, 0))]
    problems = []
    t0 = time.perf_counter()
    try:
        for tick in range(8_000):
            wire.inbox.append(good(mav.set_position_target_local_ned_encode(
                0, 1, 1, 8, MASK_SPEED_TURN_RATE, 0, 0, 0, 1.0, 0, 0, 0, 0, 0, 0, 0.2)))
            for _ in range(5):
                wire.inbox.append(pilot.fuzz.frame())
            server._drain()
            server._advance_to(server.t_us + 20_000)
            v = server.vehicle
            speed, rate = v.commands()
            s = v.state
            if not (math.isfinite(speed) and math.isfinite(rate)
                    and abs(speed) <= max_speed + 1e-9 and abs(rate) <= max_rate + 1e-9
                    and all(math.isfinite(q) for q in (s.x, s.y, s.yaw))
                    and abs(s.x) < 1e5 and abs(s.y) < 1e5):
                problems.append((tick, speed, rate, s))
        wall = time.perf_counter() - t0
    finally:
        link.close()
    fuzzed = sum(pilot.fuzz.counts.values())
    TOTALS["plant (in process)"] += fuzzed
    v = server.vehicle
    print(f"\nplant fuzz: {fuzzed} malformed frames {dict(pilot.fuzz.counts)} in {wall:.1f} s; "
          f"handler errors {server.handler_errors}, bad data {link.bad_data}, "
          f"setpoints used {v.setpoints_used}, ignored {v.setpoints_ignored}, "
          f"{len(problems)} invalid commands")
    assert fuzzed >= 40_000
    assert server.handler_errors == 0 and problems == []
    # the malformed stream neither disarmed it, nor changed its mode, nor stopped it steering
    assert v.armed and v.custom_mode == 15 and v.setpoints_used >= 7_000
    assert v.setpoints_ignored.get("non-finite", 0) + sum(v.setpoints_ignored.values()) > 1000
    assert wall < 45.0


# --- both real processes over real UDP ------------------------------------------------------
def test_fuzz_both_processes_over_udp_during_a_mission(tmp_path):
    """A companion flies an 8 s mission against the plant (paced 2 x) through a proxy that
    pours malformed frames into both of them: the mission completes, no setpoint answers bad
    data, every setpoint is finite and within the limits, the plant's handlers never raise."""
    mission = ellipse_mission(tmp_path / "m.toml", 8.0)
    to_companion = FakeVehicleStream(Wire.__new__(Wire), ticks=0, per_tick=0, seed=3)
    to_plant = PilotStream(seed=4)
    with InjectingProxy() as proxy, \
            PlantProcess("--speedup", "2", "--d-cen", "0.3", port=proxy.plant_port) as plant, \
            Companion(proxy.companion_port, "--arm", "--no-zenoh", "--json", "--mission",
                      str(mission),
                      "--max-speed", "3", "--max-yaw-rate", "2", "--log-dir",
                      str(tmp_path)) as comp:
        comp.wait_until(lambda: len(proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")) > 5,
                        20.0, "setpoints")
        while comp.proc.poll() is None:
            for seen in proxy.plant_sent("LOCAL_POSITION_NED")[-3:]:
                to_companion.fuzz.good(seen.msg.get_msgbuf())
                to_companion.ms = seen.msg.time_boot_ms
            for seen in proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")[-3:]:
                to_plant.fuzz.good(seen.msg.get_msgbuf())
            for _ in range(10):
                proxy.to_companion(to_companion.fuzz.frame())
                proxy.to_plant(to_plant.fuzz.frame())
            time.sleep(0.01)
        assert comp.wait(30.0) == 0, comp.stderr
        r = comp.result()
        plant.stop()
    n_comp, n_plant = sum(to_companion.fuzz.counts.values()), sum(to_plant.fuzz.counts.values())
    TOTALS["companion over UDP"] += n_comp
    TOTALS["plant over UDP"] += n_plant
    grid = {s.msg.time_boot_ms for s in proxy.plant_sent("LOCAL_POSITION_NED")}
    sps = proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")
    bad_answers = [s.msg.time_boot_ms for s in sps if s.msg.time_boot_ms not in grid | {0}
                   or s.msg.time_boot_ms % 25]
    invalid = [s for s in sps if not (all(math.isfinite(v) for v in (s.msg.vx, s.msg.yaw_rate))
                                      and abs(s.msg.vx) <= 3.0 and abs(s.msg.yaw_rate) <= 2.0)]
    summary = plant.stderr.strip().splitlines()[-1]
    print(f"\nUDP fuzz: {n_comp} frames into the companion, {n_plant} into the plant; "
          f"{len(sps)} setpoints, {len(bad_answers)} answering bad data, {len(invalid)} invalid; "
          f"refused {r['telemetry_rejected']}; plant: {summary}")
    print(f"fuzz totals: {dict(TOTALS)} = {sum(TOTALS.values())} frames")
    assert n_comp >= 1_000 and n_plant >= 1_000
    assert r["reason"] == "mission_done" and r["cycles"] >= 150     # of 320 ticks
    assert bad_answers == [] and invalid == []
    assert "0 handler errors" in summary
