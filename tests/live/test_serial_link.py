"""Serial links: ``sitl-plant`` and ``companion run`` on the two ends of a pseudo-terminal cable
paced like a 115200-baud UART (testbed/pty_cable.py), and the one-line errors for a device that
is absent, busy, forbidden or not a terminal."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
import tty
from contextlib import contextmanager
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from companion.core.pacing import REJOIN_NEAR
from companion.errors import UserError
from companion.mav.connection import DEFAULT_BAUD, serial_target
from testbed.scoring import batch_twin

MISSION = "missions/paper_ellipse_012.toml"
from testbed.marks import CANDIDATE
from testbed.process import ROOT, Companion, companion_cli
from testbed.pty_cable import PtyCable
from testbed.scoring import held_reference, largest_error
from testbed.sitl import ground_speed

QUICK = ("--mission", "missions/circle.toml", "--no-zenoh", "--no-log",
         "--heartbeat-timeout", "30")   # an error must come at open, long before this


@contextmanager
def plant_on(url: str, *args: str):
    proc = subprocess.Popen([sys.executable, "-m", "sitl_plant", "--connect", url, *args],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.terminate()
        try:
            proc.communicate(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()


def companion(*args: str, prefix: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    return companion_cli("run", *args, timeout=20.0, prefix=prefix)


def one_line(p: subprocess.CompletedProcess, prog: str, *needles: str) -> str:
    assert p.returncode == 2, (p.returncode, p.stderr)
    assert "Traceback" not in p.stderr, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{prog}: error: "), p.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


def cable_transit_s(baud: int) -> float:
    """Wall seconds one control cycle spends on a UART of ``baud`` (8N1): the telemetry pair
    the companion waits for, then its setpoint, each as pymavlink frames it (MAVLink 2)."""
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = (mavlink2.MAVLink_local_position_ned_message(1, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0),
              mavlink2.MAVLink_attitude_message(1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1),
              mavlink2.MAVLink_set_position_target_local_ned_message(
                  1, 1, 1, 8, 1511, *([1.0] * 11)))
    return sum(len(f.pack(mav)) for f in frames) * 10.0 / baud


@contextmanager
def pty_device():
    """A serial-like device path nobody else has open (the test holds the slave, raw)."""
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        yield os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.solo   # judged against the wall clock: alone, after the parallel run
def test_the_paper_ellipse_over_a_115200_baud_serial_link(tmp_path):
    """The plant names its baud pymavlink's way (DEVICE,BAUD), the companion with --baud."""
    with PtyCable(baud=115200) as cable, \
            plant_on(f"{cable.paths[0]},115200", "--speedup", "2", "--d-cen", "0.3") as plant, \
            Companion(None, "--baud", "115200", "--mission", MISSION, "--arm", "--json", "-q",
                      "--log-dir", str(tmp_path), url=cable.paths[1]) as comp:
        code = comp.wait(120.0)
        assert plant.poll() is None, "the plant died"
        assert code == 0, comp.stderr
        r = comp.result()
    assert r["reason"] == "mission_done" and r["hold_confirmed"]
    assert r["rate_accepted_hz"] == 40.0 and r["cycles"] == 2400
    # A link too slow for 40 Hz misses cycles by the hundred (benchmarks/serial_link.py: 871 at
    # 100 Hz over 115200 baud) and drops bytes in the cable; one late wake-up of a loaded CI
    # machine (seen once: 1 of 2400) is the scheduler, not the link. The cable's byte counts
    # below hold the link itself to zero loss.
    assert r["missed_cycles"] <= 2, (r["missed_cycles"], r["overruns"], r.get("missed_gaps"))
    assert sum(r["telemetry_rejected"].values()) == 0
    assert r["steady_rms"] <= 0.3
    # The cable is slow enough to be seen: each cycle's telemetry pair and setpoint take
    # (40 + 40 + 65 bytes) x 10 bits / 115200 baud = 12.6 ms of wall time on the wire, 25 ms of
    # vehicle time at --speedup 2, one control period. The batch twin with that transit as a
    # command delay predicts the run (f_cost 4.02, steady RMS 0.116 against 4.06 and 0.116 run
    # over the cable); without it, 3.81, which the link must not beat.
    transit = 2.0 * cable_transit_s(115200)
    assert r["f_cost"] > batch_twin(r), "faster than a zero-delay link: the cable is not in the loop"
    assert r["f_cost"] == pytest.approx(batch_twin(r, delay=transit), rel=0.08), transit
    # Every byte went through the cable, none was lost to its pace: 40 Hz fits in 115200 baud.
    assert cable.dropped == [0, 0]
    assert min(cable.carried) > 100_000, cable.carried
    assert r["setpoints_sent"] >= 2400


def test_an_unplugged_device_stops_the_run_with_exit_3():
    """The cable is cut mid-mission (a USB autopilot rebooting): the telemetry failsafes stop
    the rover and the run ends with exit 3 after --lost-timeout; stdout stays the one JSON
    result (pymavlink would print "Device ... is dead" there)."""
    with PtyCable(baud=115200) as cable, plant_on(cable.paths[0]), \
            Companion(None, "--mission", MISSION, "--arm", "--json", "--no-log",
                      "--lost-timeout", "2", url=cable.paths[1]) as comp:
        # Cut once it says it is tracking, then 1.5 s more (a fixed 8 s sleep cut one
        # loaded CI run after 29 cycles). Checked below: cycles.
        comp.wait_for_stderr("GUIDED and armed: tracking", 60.0)
        time.sleep(1.5)
        assert comp.proc.poll() is None, "the run ended before the cut"
        cable.unplug()
        cut = time.monotonic()
        code = comp.wait(30.0)
        took = time.monotonic() - cut
    assert code == 3, comp.stderr
    assert comp.stdout.strip().startswith("{") and len(comp.stdout.strip().splitlines()) == 1
    r = comp.result()
    assert r["reason"] == "failsafe: telemetry lost for 2 s" and r["failsafes"] >= 1, r
    assert r["cycles"] >= 40, r      # it was tracking (>= 1 s at 40 Hz) when the cable was cut
    assert "telemetry stale" in comp.stderr
    assert 2.0 <= took < 10.0, took


def test_serial_target_tells_devices_from_urls(tmp_path):
    assert serial_target("udpin:0.0.0.0:14550") is None
    assert serial_target("tcp:127.0.0.1:5760") is None
    assert serial_target(str(tmp_path / "flight.tlog")) is None
    log = tmp_path / "saved"
    log.write_bytes(b"")
    assert serial_target(str(log)) is None                     # an existing file: a log
    assert serial_target("/dev/ttyAMA0") == ("/dev/ttyAMA0", DEFAULT_BAUD)
    assert serial_target("/dev/ttyAMA0,921600") == ("/dev/ttyAMA0", 921600)
    assert serial_target("/dev/ttyAMA0", 57600) == ("/dev/ttyAMA0", 57600)
    assert serial_target("/dev/ttyAMA0,57600", 57600) == ("/dev/ttyAMA0", 57600)
    assert serial_target("COM3,57600") == ("COM3", 57600)
    with pytest.raises(UserError, match="two baud rates"):
        serial_target("/dev/ttyAMA0,57600", 921600)
    with pytest.raises(UserError, match="bad baud rate"):
        serial_target("/dev/ttyAMA0,fast")
    # udev's by-path names have colons, which pymavlink alone would take for a UDP address.
    with pty_device() as path:
        link = tmp_path / "pci-0000:00:14.0-usb-0:1.2:1.0"
        link.symlink_to(path)
        assert serial_target(str(link)) == (str(link), DEFAULT_BAUD)
        assert serial_target(f"{link},921600") == (str(link), 921600)


def test_a_colon_named_device_is_opened_as_serial(tmp_path):
    """Through the symlink the companion reaches the plant (it would otherwise bind UDP)."""
    with PtyCable() as cable, plant_on(cable.paths[0], "--speedup", "4"):
        link = tmp_path / "usb-0:1.2:1.0"
        link.symlink_to(cable.paths[1])
        p = companion("--connect", str(link), "--mission", "missions/circle.toml", "--no-zenoh",
                      "--no-log", "--heartbeat-timeout", "10", "--arm-timeout", "0.5")
    # Not armed (no --arm), so it stops once set up; it saw the vehicle, which only the serial
    # open of the symlink's pty allows.
    assert "ardupilot vehicle, system 1" in p.stderr, p.stderr
    assert "cannot open" not in p.stderr and "no heartbeat" not in p.stderr, p.stderr


def test_absent_device_is_one_line():
    t0 = time.monotonic()
    line = one_line(companion("--connect", "/dev/ttyNOPE", *QUICK), "companion run",
                    "/dev/ttyNOPE", "no such device")
    assert time.monotonic() - t0 < 10.0, line
    one_line(companion("--connect", "/dev/ttyNOPE", "--baud", "921600", *QUICK),
             "companion run", "/dev/ttyNOPE")
    p = subprocess.run([sys.executable, "-m", "sitl_plant", "--connect", "/dev/ttyNOPE,57600"],
                       capture_output=True, text=True, timeout=20.0)
    one_line(p, "sitl-plant", "/dev/ttyNOPE", "no such device")


def test_busy_device_is_one_line():
    """Another process holds the port exclusively (pyserial's exclusive=True, as the companion
    and the plant do themselves): the second opener is refused at once, not fed half the bytes."""
    serial = pytest.importorskip("serial")
    with pty_device() as path:
        holder = serial.Serial(path, 115200, exclusive=True)
        try:
            one_line(companion("--connect", path, *QUICK), "companion run", path, "busy")
            p = subprocess.run([sys.executable, "-m", "sitl_plant", "--connect", path],
                               capture_output=True, text=True, timeout=20.0)
            one_line(p, "sitl-plant", path, "busy")
        finally:
            holder.close()
        # Free again once the holder lets go: the same open now gets to waiting for a vehicle.
        p = companion("--connect", path, "--mission", "missions/circle.toml", "--no-zenoh",
                      "--no-log", "--heartbeat-timeout", "0.5")
        one_line(p, "companion run", "no heartbeat")


def opened_by(pid: int, path: str) -> bool:
    fds = Path(f"/proc/{pid}/fd")
    try:
        return any(os.readlink(fd) == path for fd in fds.iterdir())
    except OSError:
        return False


def test_the_companion_holds_its_port_exclusively():
    with pty_device() as path:
        proc = subprocess.Popen([sys.executable, "-m", "companion", "run", "--connect", path,
                                 *QUICK], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                text=True, cwd=ROOT)
        try:
            deadline = time.monotonic() + 15.0
            while not opened_by(proc.pid, path):
                assert time.monotonic() < deadline and proc.poll() is None, "never opened"
                time.sleep(0.05)
            p = subprocess.run([sys.executable, "-m", "sitl_plant", "--connect", path,
                                "--duration", "1"], capture_output=True, text=True, timeout=20.0)
            one_line(p, "sitl-plant", path, "busy")
        finally:
            proc.kill()
            proc.communicate()


def test_permission_denied_is_one_line():
    """A device the user may not open (mode 000; root runs without CAP_DAC_OVERRIDE)."""
    prefix: tuple[str, ...] = ()
    if os.geteuid() == 0:
        if shutil.which("setpriv") is None:
            pytest.skip("running as root and setpriv (util-linux) is absent: root opens anything")
        prefix = ("setpriv", "--bounding-set=-dac_override,-dac_read_search", "--")
    with pty_device() as path:
        os.chmod(path, 0)
        one_line(companion("--connect", path, *QUICK, prefix=prefix), "companion run", path,
                 "permission denied")


def test_not_a_terminal_and_bad_baud_are_one_line(tmp_path):
    one_line(companion("--connect", "/dev/null", *QUICK), "companion run", "/dev/null",
             "not a serial device")
    one_line(companion("--connect", "/dev/ttyNOPE,fast", *QUICK), "companion run",
             "bad baud rate", "fast")
    one_line(companion("--connect", "/dev/ttyNOPE,57600", "--baud", "921600", *QUICK),
             "companion run", "two baud rates", "57600", "921600")
    p = companion("--connect", "/dev/ttyNOPE", "--baud", "-9600", *QUICK)
    assert p.returncode == 2 and "argument --baud: must be > 0" in p.stderr, p.stderr


def _serial_sitl(workdir: Path, device: str, speedup: float):
    """ArduPilot SITL with its SERIAL2 (its own UART driver, MAVLink 2 at 921600) on
    ``device``; SERIAL0 (TCP) is for a ground station, which SITL needs before it boots."""
    from testbed.ardupilot import ArduPilotSITL

    class SerialSITL(ArduPilotSITL):
        def argv(self) -> list[str]:
            return super().argv() + ["--serial2", f"uart:{device}:921600"]

    return SerialSITL(workdir, speedup=speedup,
                      params={"SERIAL2_PROTOCOL": 2, "SERIAL2_BAUD": 921})


@pytest.mark.sitl
@pytest.mark.slow
@CANDIDATE   # 9 of 10 on 2026-12-02: 1330 bytes over the pty's 4 kB buffer once, load 11
def test_ardupilot_sitl_over_its_own_uart_driver(tmp_path):
    """ArduPilot SITL's SERIAL2 is its UART driver on one end of the cable (a real autopilot's
    serial code, MAVLink 2 at 921600), the companion on the other; SERIAL0 (TCP) is a ground
    station, which SITL needs before it boots."""
    from testbed.ardupilot import GroundStation
    from testbed.missions import circle_mission

    speedup = 2
    mission = circle_mission(tmp_path / "circle.toml", duration=20.0)
    with PtyCable(baud=921600) as cable, \
            _serial_sitl(tmp_path / "ardupilot", cable.paths[0], speedup).start() as sitl, \
            GroundStation(sitl, serial=0), \
            Companion(None, "--baud", "921600", "--mission", str(mission), "--arm", "--json",
                      "--no-zenoh", "--log-dir", str(tmp_path / "logs"), "--arm-timeout",
                      "120", url=cable.paths[1]) as comp:
        code = comp.wait(240.0)
        assert code == 0, comp.stderr + sitl.log_tail()
        r = comp.result()
    assert r["reason"] == "mission_done" and r["hold_confirmed"], r
    assert r["autopilot"] == "ardupilot" and r["rate_accepted_hz"] == 40.0
    assert r["missed_cycles"] <= 0.01 * r["cycles"] and r["cycles"] >= 0.98 * 20.0 * 40.0, r
    assert r["steady_rms"] < 0.3, r["steady_rms"]
    assert cable.dropped == [0, 0]
    print(f"\nArduPilot SITL over a 921600-baud pty: steady RMS {r['steady_rms']:.3f} m, "
          f"f_cost {r['f_cost']:.3f}, {r['cycles']} cycles, missed {r['missed_cycles']}, "
          f"loop {r['loop_rate_hz']:.1f} Hz; bytes carried {cable.carried}")


@pytest.mark.sitl
@pytest.mark.slow
def test_a_serial_link_stall_stops_the_rover_and_the_mission_completes(tmp_path):
    """Issue 21's link stall on a serial link: the cable between ArduPilot SITL's UART and the
    companion loses every byte both ways for 10 s of vehicle time (a telemetry radio's fade:
    nothing queues, unlike TCP), 15 s into tracking. ArduPilot's guided timeout stops the rover
    3 s in; the companion's stale-telemetry failsafe holds its reference; once bytes flow again
    it re-engages GUIDED and the mission completes. The ground station on SERIAL0 (TCP) watches
    the pose and times the stall on the vehicle's clock."""
    from testbed.ardupilot import GUIDED, GroundStation
    from testbed.missions import circle_mission

    speedup, stall_s = 2, 10.0
    mission = circle_mission(tmp_path / "circle.toml", duration=40.0)
    with PtyCable(baud=921600) as cable, \
            _serial_sitl(tmp_path / "ardupilot", cable.paths[0], speedup).start() as sitl, \
            GroundStation(sitl, serial=0) as gs, \
            Companion(None, "--baud", "921600", "--mission", str(mission), "--arm", "--json",
                      "--no-zenoh", "--log-dir", str(tmp_path / "logs"), "--arm-timeout",
                      "120", url=cable.paths[1]) as comp:
        deadline = time.monotonic() + 60.0
        while True:      # SITL may not answer at once on a loaded machine (set-up)
            try:
                assert gs.set_rate(32, 10.0) == 0          # LOCAL_POSITION_NED
                break
            except AssertionError:
                assert time.monotonic() < deadline, sitl.log_tail()
        gs.wait_for("HEARTBEAT", lambda m: m.custom_mode == GUIDED and m.base_mode & 128, 150.0)
        moving = gs.wait_for("LOCAL_POSITION_NED", lambda m: ground_speed(m) > 0.5, 60.0)
        gs.wait_for("LOCAL_POSITION_NED",
                    lambda m: m.time_boot_ms >= moving.time_boot_ms + 15_000, 60.0)
        t_stall = time.monotonic()
        cable.stall()
        first = gs.wait_for("LOCAL_POSITION_NED", timeout=10.0, after=t_stall)
        gs.wait_for("LOCAL_POSITION_NED",
                    lambda m: m.time_boot_ms >= first.time_boot_ms + 1000 * stall_s - 100, 60.0)
        cable.resume()
        t_back = time.monotonic()
        code = comp.wait(180.0)
        r = comp.result()
        poses = gs.messages("LOCAL_POSITION_NED", t_stall)
        poses = [m for m in poses if m.time_boot_ms <= first.time_boot_ms + 1000 * stall_s]
        lost = list(cable.lost)
    t0 = poses[0].time_boot_ms
    late = [ground_speed(m) for m in poses if m.time_boot_ms >= t0 + 6000]
    err = largest_error(r["csv"], 5.0)
    paused_s, ref_moved_s, err_back = held_reference(r["csv"])
    print(f"\nSerial stall {stall_s:g} s (921600-baud pty, both ways lost: {lost} bytes): speed "
          f"at the start {ground_speed(poses[0]):.2f} m/s, max {max(late):.2f} m/s from 6 s on; "
          f"tracking paused {paused_s:.1f} s (vehicle), the reference moved {ref_moved_s:.3f} s "
          f"meanwhile, error {err_back:.2f} m on taking up; largest tracking error from 5 s of mission on {err:.2f} m (the rover ran "
          f"on its last setpoint for ArduPilot's 3 s guided timeout); exit {code}: "
          f"{r['reason']}, failsafes {r['failsafes']}, {r['duration_s']:.1f} s of mission "
          f"tracked, {t_back - t_stall:.1f} s wall")
    assert code == 0 and r["reason"] == "mission_done", comp.stderr + sitl.log_tail()
    assert "telemetry stale" in comp.stderr and "pilot took over" not in comp.stderr
    assert r["duration_s"] >= 40.0 - 1e-6
    assert min(lost) > 0, lost
    assert max(late) < 0.2, late
    # the mission clock stood still through the stall and took up where the rover came to
    # rest: on by what it ran on its last setpoint (ArduPilot's 3 s guided timeout, braking),
    # no further
    assert paused_s >= stall_s - 1.0, paused_s
    assert ref_moved_s <= 6.0 and err_back <= REJOIN_NEAR, (ref_moved_s, err_back)
