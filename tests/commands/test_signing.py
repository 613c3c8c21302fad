"""MAVLink 2 signing on both ends: key files, a signed pair end to end, and strangers (unsigned
or signed with another key) who can neither command the plant nor feed the companion.
Real processes over loopback UDP."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

from companion.errors import UserError
from companion.mav.signing import load_key
from sitl_plant.testing import MASK_SPEED_TURN_RATE, Pilot, PlantProcess
from testbed.fake_vehicle import is_zero
from testbed.missions import ellipse_mission
from testbed.process import ROOT, Companion
from testbed.safety import GUIDED, InjectingProxy, encoder, frame, make_key, read_tlog


# --- key files ---------------------------------------------------------------------------------
def test_key_files_raw_and_hex_are_loaded(tmp_path):
    raw = make_key(tmp_path / "raw.key")
    assert load_key(str(raw)) == raw.read_bytes()
    secret = bytes(range(32))
    hexed = make_key(tmp_path / "hex.key", data=(secret.hex() + "\n").encode())
    assert load_key(str(hexed)) == secret


@pytest.mark.parametrize("case, expect", [
    ("missing", "no such file"),
    ("world", "other users can access the key (mode 0644); run: chmod 600"),
    ("group", "mode 0640"),
    ("short", "exactly 32 bytes or 64 hex digits, this file has 31 bytes"),
    ("badhex", "this file has 65 bytes"),
    ("dir", "not a regular file"),
])
def test_bad_key_files_are_one_line_errors(tmp_path, case, expect):
    path = tmp_path / "k"
    if case == "world":
        make_key(path, 0o644)
    elif case == "group":
        make_key(path, 0o640)
    elif case == "short":
        make_key(path, data=b"x" * 31)
    elif case == "badhex":
        make_key(path, data=b"z" * 64 + b"\n")
    elif case == "dir":
        path.mkdir(mode=0o700)
    with pytest.raises(UserError) as err:
        load_key(str(path))
    assert expect in str(err.value) and str(path) in str(err.value)
    assert "--signing-key" in str(err.value)


def test_bad_key_on_the_command_line_exits_2_without_traceback(tmp_path):
    key = make_key(tmp_path / "k", 0o644)
    for argv in (["-m", "companion", "run", "--no-zenoh", "--mission", "missions/circle.toml",
                  "--signing-key", str(key), "--log-dir", str(tmp_path)],
                 ["-m", "sitl_plant", "--signing-key", str(key)]):
        p = subprocess.run([sys.executable, *argv], capture_output=True, text=True, cwd=ROOT,
                           timeout=30)
        assert p.returncode == 2, p.stderr
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and "chmod 600" in lines[0] and "Traceback" not in p.stderr


# --- a signed pair ------------------------------------------------------------------------------
def test_a_signed_pair_flies_end_to_end_and_logs_signed_frames(tmp_path):
    key = make_key(tmp_path / "k")
    p = subprocess.run([sys.executable, "-m", "companion", "demo", "--no-zenoh", "--json",
                        "--no-plot", "-q",
                        "--duration", "10", "--signing-key", str(key), "--log-dir",
                        str(tmp_path)], capture_output=True, text=True, cwd=ROOT, timeout=90)
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout.strip().splitlines()[-1])
    assert r["reason"] == "mission_done" and r["hold_confirmed"] and r["signing_rejected"] == 0
    assert r["cycles"] == 400 and r["steady_rms"] < 0.3
    frames, bad = read_tlog(tmp_path / r["tlog"].split("/")[-1])
    assert bad == 0 and len(frames) > 1000
    # every frame of the run, both directions, carries a signature (incompat_flags bit 0)
    assert all(m.get_msgbuf()[2] & 1 for _, m in frames)
    # the vehicle (1, 1) and the companion, a component of its system (1, 191)
    assert {(m.get_srcSystem(), m.get_srcComponent()) for _, m in frames} == {(1, 1), (1, 191)}


# --- strangers against the plant ---------------------------------------------------------------
def _attempt(proxy_send, mav) -> int:
    """Arm, GUIDED, and a second of full-speed setpoints from one sender; frames sent."""
    sent = 0
    for msg in (mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0),
                mav.command_long_encode(1, 1, 176, 0, 1, GUIDED, 0, 0, 0, 0, 0)):
        proxy_send(frame(mav, msg))
        sent += 1
        time.sleep(0.05)
    for _ in range(20):
        proxy_send(frame(mav, mav.set_position_target_local_ned_encode(
            0, 1, 1, 8, MASK_SPEED_TURN_RATE, 0, 0, 0, 3.0, 0, 0, 0, 0, 0, 0, 0.5)))
        sent += 1
        time.sleep(0.05)
    return sent


def test_unsigned_and_wrong_key_senders_cannot_arm_switch_or_steer_the_plant(tmp_path):
    key = make_key(tmp_path / "k")
    with PlantProcess("--speedup", "2", "--signing-key", str(key)) as plant, \
            Pilot(plant.port) as watch:          # no key: reads the plant's signed frames
        watch.wait("HEARTBEAT", 5.0)
        plant_addr = next(iter(watch.conn.clients))

        def send(data):
            watch.conn.port.sendto(data, plant_addr)

        refused = 0
        for mav in (encoder(None), encoder(bytes(32)), encoder(b"\x01" * 32)):
            refused += _attempt(send, mav)
            acks = [m for m in watch.collect(("COMMAND_ACK",), 0.3)]
            assert acks == [], "a stranger's command was answered"
            hb = watch.wait("HEARTBEAT", 3.0)
            assert hb.custom_mode == 0 and not hb.base_mode & 128    # MANUAL, disarmed
        # the key holder is obeyed: the same attempt, signed with the key, arms and steers
        good = encoder(key.read_bytes())
        send(frame(good, good.command_long_encode(1, 1, 511, 0, 32, 50_000, 0, 0, 0, 0, 0)))
        _attempt(send, good)
        hb = watch.wait("HEARTBEAT", 3.0, lambda m: m.custom_mode == GUIDED and m.base_mode & 128)
        moving = watch.wait("LOCAL_POSITION_NED", 3.0, lambda m: m.vx ** 2 + m.vy ** 2 > 0.25)
        assert hb and moving
        code = plant.stop()
    assert code == 0
    summary = plant.stderr.strip().splitlines()[-1]
    assert f"{refused} refused for their signature" in summary, summary
    assert "0 handler errors" in summary


# --- strangers against the companion -----------------------------------------------------------
def test_the_companion_ignores_unsigned_and_wrong_key_telemetry(tmp_path):
    """A signed companion tracks a signed plant while unsigned and wrong-key frames pretending
    to be the vehicle (poses, attitudes, a HOLD heartbeat) pour into its port: none is used."""
    key = make_key(tmp_path / "k")
    mission = ellipse_mission(tmp_path / "m.toml", 16.0)
    injected = 0
    with InjectingProxy() as proxy, \
            PlantProcess("--speedup", "2", "--d-cen", "0.3", "--signing-key", str(key),
                         port=proxy.plant_port), \
            Companion(proxy.companion_port, "--arm", "--no-zenoh", "--json", "--mission",
                      str(mission),
                      "--signing-key", str(key), "--log-dir", str(tmp_path)) as comp:
        comp.wait_until(lambda: len(proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")) > 20,
                        20.0, "setpoints")
        strangers = [encoder(None, sysid=1, compid=1), encoder(b"\x02" * 32, sysid=1, compid=1)]
        # Inject over 6 s of vehicle time (of the mission's 16), at most 2000 frames: a window
        # set by the vehicle's clock, so a loaded machine injects fewer frames, not later ones.
        t_end = proxy.plant_sent("LOCAL_POSITION_NED")[-1].msg.time_boot_ms + 6000
        while comp.proc.poll() is None and injected < 2000:
            last = proxy.plant_sent("LOCAL_POSITION_NED")[-1].msg.time_boot_ms
            if last >= t_end:
                break
            for mav in strangers:
                ms = last + 13          # off the plant's 25 ms grid: recognisable if answered
                for msg in (mav.heartbeat_encode(10, 3, 1, HOLD_MODE, 4),
                            mav.attitude_encode(ms, 0, 0, 1.0, 0, 0, 0),
                            mav.local_position_ned_encode(ms, 50.0, -50.0, 0, 9.0, 9.0, 0)):
                    proxy.to_companion(frame(mav, msg))
                    injected += 1
            time.sleep(0.01)
        # The strangers shared the plant's socket, so they reached the companion's port before
        # any pose sent after them: a setpoint answering such a pose means all were read.
        t_last = time.monotonic()
        proxy.wait_for(lambda: proxy.plant_sent("LOCAL_POSITION_NED", after=t_last), 5.0)
        after_ms = proxy.plant_sent("LOCAL_POSITION_NED", after=t_last)[0].msg.time_boot_ms
        comp.wait_until(lambda: any(s.msg.time_boot_ms >= after_ms for s in proxy.companion_sent(
            "SET_POSITION_TARGET_LOCAL_NED")), 10.0, "a setpoint after the last stranger")
        assert comp.wait(60.0) == 0, comp.stderr
        r = comp.result()
    assert injected >= 300
    assert r["reason"] == "mission_done"
    # No failsafe the strangers caused: a loaded machine may stall the plant past the stale
    # timeout (a failsafe for silence, and back: seen once beside a SITL suite), nothing else,
    # and no genuine sample was refused.
    stops = [line for line in comp.stderr.splitlines() if "stopping the rover" in line]
    assert r["failsafes"] == len(stops), comp.stderr
    assert all("telemetry stale" in line for line in stops), stops
    assert sum(r["telemetry_rejected"].values()) == 0, r["telemetry_rejected"]
    assert r["signing_rejected"] >= injected
    sps = proxy.companion_sent("SET_POSITION_TARGET_LOCAL_NED")
    assert all(s.msg.time_boot_ms % 25 == 0 for s in sps), "a setpoint answered injected data"
    # the stranger's HOLD heartbeat was no "pilot takeover": the mission ran to its end
    assert sum(1 for s in sps if not is_zero(s.msg)) >= 300


HOLD_MODE = 4
