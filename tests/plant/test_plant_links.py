"""The plant over other mavutil connection strings (udpin, tcpin, tcp) and with impaired
telemetry (noise, dropout, latency), end to end."""

from __future__ import annotations

import socket
import statistics
import time

import pytest

from sitl_plant.testing import Pilot, PlantProcess, free_port, free_udp_port, speed_of


def free_tcp_port() -> int:
    return free_port(socket.SOCK_STREAM)


def wait_listening(port: int, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise AssertionError(f"nothing listens on {port}")


def test_udpin_replies_to_whoever_talks_to_it():
    port = free_udp_port()
    with PlantProcess("--connect", f"udpin:127.0.0.1:{port}", "--speedup", "4"), \
            Pilot(port, url=f"udpout:127.0.0.1:{port}") as pilot:
        hb = None
        for _ in range(20):                    # the plant only knows us once we have spoken
            pilot.mav.heartbeat_send(6, 8, 0, 0, 0)
            try:
                hb = pilot.wait("HEARTBEAT", 0.5)
                break
            except AssertionError:
                continue
        assert hb is not None and hb.type == 10
        assert pilot.set_mode(15) == 0 and pilot.arm() == 0


def test_tcpin_serves_a_tcp_client():
    port = free_tcp_port()
    with PlantProcess("--connect", f"tcpin:127.0.0.1:{port}", "--speedup", "4") as plant:
        wait_listening(port)
        with Pilot(port, url=f"tcp:127.0.0.1:{port}") as pilot:
            assert pilot.wait("HEARTBEAT").autopilot == 3
            assert pilot.set_mode(15) == 0
        with Pilot(port, url=f"tcp:127.0.0.1:{port}") as pilot:   # the next client after EOF
            assert pilot.wait("HEARTBEAT").custom_mode == 15
        assert plant.alive()


def test_tcp_client_connects_and_exits_when_the_peer_hangs_up():
    port = free_tcp_port()
    pilot = Pilot(port, url=f"tcpin:127.0.0.1:{port}")
    try:
        with PlantProcess("--connect", f"tcp:127.0.0.1:{port}", "--speedup", "4") as plant:
            assert pilot.wait("HEARTBEAT").type == 10
            assert pilot.arm() == 0
            pilot.conn.close()
            assert plant.proc.wait(timeout=5.0) == 0       # it stops on its own
            plant.stop()
        assert "TCP peer closed the connection" in plant.stderr
    finally:
        pilot.conn.close()


def test_noise_and_dropout_on_pose_telemetry():
    with PlantProcess("--speedup", "4", "--noise-pos", "0.2", "--noise-yaw", "0.05",
                      "--dropout", "0.3", "--seed", "3") as plant, Pilot(plant.port) as pilot:
        pilot.wait("HEARTBEAT")
        assert pilot.set_rate(32, 40) == 0
        msgs = pilot.collect(("LOCAL_POSITION_NED",), 1.5)
        ticks = (msgs[-1].time_boot_ms - msgs[0].time_boot_ms) / 25 + 1
        assert 0.6 < len(msgs) / ticks < 0.8               # about 30 % lost
        assert statistics.pstdev(m.x for m in msgs) == pytest.approx(0.2, rel=0.25)
        assert all(speed_of(m) == 0.0 for m in msgs)       # velocities are not noisy


def test_latency_delays_telemetry_in_vehicle_time():
    with PlantProcess("--speedup", "4", "--latency", "1.0") as plant, Pilot(plant.port) as pilot:
        pilot.wait("HEARTBEAT")
        assert pilot.set_rate(32, 20) == 0
        assert pilot.set_mode(15) == 0 and pilot.arm() == 0
        pilot.drain()
        pilot.speed_turn_rate(1.0, 0.0)                    # one target; 3 s later it times out
        moving = pilot.wait("LOCAL_POSITION_NED", 5.0, lambda m: speed_of(m) > 0.0)
        seen = moving
        while True:                                        # the last pose before the timeout text
            msg = pilot.conn.recv_match(blocking=True, timeout=3.0)
            assert msg is not None
            if msg.get_type() == "STATUSTEXT" and "3secs" in msg.text:
                break
            if msg.get_type() == "LOCAL_POSITION_NED":
                seen = msg
        # the text leaves at once, poses 1 s late: the newest pose is ~2 s after motion began
        assert 1.9 <= (seen.time_boot_ms - moving.time_boot_ms) / 1000.0 <= 2.1
