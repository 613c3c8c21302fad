"""A scripted ArduPilot-like rover for the companion (:class:`FakeVehicle`), and what a test asks
of the frames the companion sent it (a zero setpoint, a mode command, a finite setpoint).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

from pymavlink import mavutil

from .link_thread import LinkThread


def is_zero(sp: Any) -> bool:
    return sp.vx == 0.0 and sp.vy == 0.0 and sp.yaw_rate == 0.0


def is_mode_command(msg: Any, mode: int) -> bool:
    return msg.command == 176 and int(msg.param2) == mode


@dataclass
class FakeVehicle(LinkThread):
    """A scripted ArduPilot-like rover for the companion, on pymavlink, in a thread.

    Answers SET_MESSAGE_INTERVAL, DO_SET_MODE and ARM with ACCEPTED, PARAM_REQUEST_READ with 0; streams ATTITUDE +
    LOCAL_POSITION_NED one tick at a time, going on when a setpoint answered the tick or after
    ``tick_timeout`` wall seconds. ``script(k, ms) -> dict`` can change tick k: keys ``x, vx``
    (LOCAL_POSITION_NED), ``yaw`` (ATTITUDE), ``ms`` (time_boot_ms), ``sysid`` (sender), or
    ``restart`` (reboot: back to MANUAL, disarmed), ``reboot`` (the same as a real autopilot does it:
    its clock from ``ms``, no heartbeat for ``reboot_gap`` s, then heartbeats only: nothing
    streamed until asked again; it answers MAV_CMD_REQUEST_MESSAGE for SYSTEM_TIME); the autopilot's own doings: ``ekf`` (an
    EKF_STATUS_REPORT with these flags), ``gps`` (a GPS_RAW_INT: (fix type, h_acc mm)), ``text`` (a STATUSTEXT), ``status`` (the heartbeat's
    system_status from now on), ``mode`` (it switches mode itself), ``silent`` (no pose this
    tick), ``attitude`` (False: a LOCAL_POSITION_NED without an ATTITUDE this tick); the link:
    ``deaf`` (nothing the companion sends arrives this tick: kept in ``lost``).
    Records every setpoint and command.
    """

    port: int
    script: Any = None
    start_ms: int = 100_000
    step_ms: int = 25
    tick_timeout: float = 0.02
    reboot_gap: float = 1.0
    setpoints: list[Any] = field(default_factory=list)
    commands: list[Any] = field(default_factory=list)
    sent_ms: list[tuple[int, str]] = field(default_factory=list)   # (time_boot_ms, note)
    lost: list[Any] = field(default_factory=list)     # what the companion sent while deaf

    def __post_init__(self):
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{self.port}", source_system=1,
                                               source_component=1, dialect="ardupilotmega")
        self.mode, self.armed, self.streaming = 0, False, False
        self.system_status = 4                   # MAV_STATE_ACTIVE
        self.deaf, self.ms, self.booting = False, self.start_ms, False
        self.rebooting_until = 0.0
        self._prepare_thread()

    def _heartbeat(self) -> None:
        if time.monotonic() < self.rebooting_until:
            return                               # rebooting: silent
        base = 1 | (128 if self.armed else 0) | (8 if self.mode == 15 else 0)
        self.conn.mav.heartbeat_send(10, 3, base, self.mode, self.system_status)

    def _handle(self, msg: Any) -> bool:
        """True when the message is a setpoint (it answers the tick)."""
        kind = msg.get_type()
        if time.monotonic() < self.rebooting_until:          # rebooting: hears nothing
            if kind == "COMMAND_LONG":
                self.commands.append(msg)
            return False
        if self.deaf:
            self.lost.append(msg)
            return False
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            self.setpoints.append(msg)
            return True
        if kind == "PARAM_REQUEST_READ":
            # as an autopilot answers (every parameter 0 here): run's preset look-up, without
            # which it would wait its read timeout while the script's ticks went by
            name = msg.param_id.encode() if isinstance(msg.param_id, str) else msg.param_id
            self.conn.mav.param_value_send(name, 0.0, 9, 1, 0)
            return False
        if kind == "COMMAND_LONG":
            self.commands.append(msg)
            if self.booting and msg.command in (176, 400):
                # a rebooted autopilot still starting: no mode change, no arming yet
                self.conn.mav.command_ack_send(msg.command, 4)        # MAV_RESULT_FAILED
                return False
            if msg.command == 511:
                self.streaming = True
            elif msg.command == 512 and int(msg.param1) == 2:     # SYSTEM_TIME, once
                self.conn.mav.system_time_send(0, self.ms)
            elif msg.command == 176:
                self.mode = int(msg.param2)
            elif msg.command == 400:
                self.armed = msg.param1 == 1.0
            self.conn.mav.command_ack_send(msg.command, 0)
            self._heartbeat()
        return False

    def _pump(self, timeout: float) -> bool:
        deadline, answered = time.monotonic() + timeout, False
        while not answered and (left := deadline - time.monotonic()) > 0:
            msg = self.conn.recv_match(blocking=True, timeout=min(left, 0.005))
            if msg is not None:
                answered = self._handle(msg) or answered
        return answered

    def _run(self) -> None:
        ms, k, next_hb = self.start_ms, 0, 0.0
        while not self._stop.is_set():
            if time.monotonic() >= next_hb:
                self._heartbeat()
                next_hb = time.monotonic() + 0.1
            if not self.streaming:
                self._pump(0.02)
                continue
            tick = {"x": 0.0, "y": 0.0, "vx": 0.0, "yaw": 0.0, "ms": ms, "sysid": 1}
            if self.script is not None:
                tick.update(self.script(k, ms) or {})
            if tick.get("restart") or tick.get("reboot"):
                ms = tick["ms"]
                tick["ms"] = ms
                self.mode, self.armed = 0, False
                if tick.get("reboot"):
                    self.streaming, self.ms, self.booting = False, ms, True
                    self.rebooting_until = time.monotonic() + self.reboot_gap
                    continue
            self.ms = tick["ms"]
            self.deaf = bool(tick.get("deaf"))
            mav = self.conn.mav
            if "status" in tick:
                self.system_status = tick["status"]
            if "text" in tick:                  # an autopilot says why before it acts
                mav.statustext_send(2, tick["text"].encode())
            if "mode" in tick:
                self.mode = tick["mode"]
            if "status" in tick or "mode" in tick:
                # heard at once: the script counts ticks, which pass as fast as the companion
                # answers, while the 10 Hz heartbeat counts wall time
                self._heartbeat()
            if "ekf" in tick:
                mav.ekf_status_report_send(tick["ekf"], 0.1, 0.1, 0.1, 0.1, 0.0)
            if "gps" in tick:                   # (fix_type, h_acc mm): the receiver's class
                fix, h_acc = tick["gps"]
                mav.gps_raw_int_send(tick["ms"] * 1000, fix, 473977420, 85455940, 0, 80, 120, 0,
                                     0, 20, 0, h_acc, 2 * h_acc, 50, 0)
            if tick.get("silent"):
                self._pump(self.tick_timeout)
                ms += self.step_ms
                k += 1
                continue
            mav.srcSystem = tick["sysid"]
            if tick.get("attitude", True):
                mav.attitude_send(tick["ms"], 0.0, 0.0, tick["yaw"], 0.0, 0.0, 0.0)
            mav.local_position_ned_send(tick["ms"], tick["x"], tick["y"], 0.0, tick["vx"],
                                        0.0, 0.0)
            mav.srcSystem = 1
            self.sent_ms.append((tick["ms"], tick.get("note", "")))
            self._pump(self.tick_timeout)
            ms += self.step_ms
            k += 1

    def answered(self, ms: int) -> int:
        return sum(1 for sp in self.setpoints if sp.time_boot_ms == ms)


def finite_setpoint(sp: Any) -> bool:
    return all(math.isfinite(v) for v in (sp.vx, sp.vy, sp.yaw_rate))
