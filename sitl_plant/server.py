"""The plant process: the vehicle on a clock, telemetry out, commands and setpoints in.

One thread, one loop. Vehicle time is integer microseconds on a fixed physics step; telemetry,
heartbeat and timers fall on that grid. Paced mode keeps vehicle time at wall time x speedup and
brings the physics up to "now" before handling each message, so a setpoint acts at the vehicle
time it arrived. Lockstep mode (while a companion is streaming setpoints) runs from one
telemetry tick to the next as soon as a setpoint has answered the last one, so a run is
deterministic and as fast as the two processes go.

A pilot takeover (``takeover_at`` vehicle seconds, or :meth:`PlantServer.pilot_takeover` from a
SIGUSR1) flips the vehicle to HOLD as a pilot's mode switch would, and announces it at once with
a heartbeat and a STATUSTEXT (ArduPilot's own heartbeat may take up to its 1 s period).
"""

from __future__ import annotations

import math
import select
import socket
import time
from collections.abc import Callable
from typing import Any

from companion.profiles.setpoint import Setpoint

from . import params, status, streams
from .auto import Auto
from .clock import LockstepGate, Pacer
from .config import PlantConfig
from .earth import Earth, e7
from .link import Link
from .mission import MissionStore
from .modes import hold_mode
from .telemetry import TelemetryPipe
from .vehicle import Result, Vehicle

MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_GET_MESSAGE_INTERVAL = 510
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
MSG_ID_SET_MODE = 11
FLAG_CUSTOM_MODE_ENABLED = 1
SEVERITY_WARNING = 4
MAX_WAIT = 0.1  # wall s: the loop wakes at least this often (signals, lockstep bookkeeping)


class PlantServer:
    def __init__(self, config: PlantConfig, link: Link, vehicle: Vehicle | None = None,
                 wall: Callable[[], float] = time.monotonic, gcs: Link | None = None):
        self.config = config
        self.link = link
        # --gcs URL: a second link, a ground station's (ArduPilot's SERIAL1 / telemetry radio):
        # heartbeats and texts to it, its commands and mission transfers answered on it, and
        # messages routed between it and the companion's link as ArduPilot's MAVLink routing
        # does (what is not addressed to the plant alone goes across); no pose streams on it.
        self.gcs = gcs
        self.mission = MissionStore(drop_item=config.mission_drop_item)
        self._current_sent = 0            # MISSION_CURRENT last announced (0 at boot)
        self.vehicle = vehicle or Vehicle(config.vehicle)
        self.wall = wall
        gpi = config.global_position_rate
        self.streams = streams.StreamSchedule(
            config.loop_rate, tick_aligned=config.tick_aligned,
            initial={streams.GLOBAL_POSITION_INT: int(round(1e6 / gpi)) if gpi > 0 else None,
                     streams.EKF_STATUS_REPORT: None,
                     streams.MISSION_CURRENT: None})
        self.earth = Earth(config.origin, config.vehicle.start[:2])
        self._after_ack: list[Callable[[], None]] = []
        self.telemetry = TelemetryPipe(config.telemetry)
        self.pacer = Pacer(config.speedup)
        self.gate = LockstepGate(config.lockstep_timeout)
        self.dt_us = max(1, int(round(config.physics_dt * 1e6)))
        self.end_us = None if config.duration is None else int(round(config.duration * 1e6))
        self.stopping = False
        self.wake: socket.socket | None = None  # becomes readable when a signal arrives
        self.foreign = 0                  # messages addressed to another system
        self.handler_errors = 0           # well-formed frames whose handling raised
        self.takeover_requested = False   # set by SIGUSR1
        self._takeover_us = (None if config.takeover_at is None
                             else int(round(config.takeover_at * 1e6)))
        self._battery_low_us = (None if config.battery_low_at is None
                                else int(round(config.battery_low_at * 1e6)))
        self.battery_ok = True
        v = self.vehicle.config
        self.params = params.ParamTable(
            v.autopilot.plant.params(v.params, config.loop_rate, config.sysid,
                                     v.offboard_loss_timeout),
            bytewise=v.autopilot.bytewise_params, overrides=config.params,
            loss=config.param_loss, seed=config.telemetry.seed)
        self._update_mav_type()
        if self.vehicle.autopilot.auto_mode is not None:
            self.vehicle.auto = Auto(self.mission, self.earth.origin)

    def _update_mav_type(self) -> None:
        self.link.mav_type = (self.config.mav_type if self.config.mav_type is not None
                              else self.params.mav_type())

    def _status_sensors(self) -> tuple[int, int, int]:
        """SYS_STATUS's pre-arm bit: healthy once arming would be accepted."""
        return status.sensors(self.vehicle.t >= self.vehicle.config.arm_delay, self.battery_ok)

    @property
    def t_us(self) -> int:
        """Vehicle time since boot, microseconds: the vehicle's own clock."""
        return self.vehicle.t_us

    # --- the loop ---------------------------------------------------------------------------
    def run(self) -> None:
        self.pacer.anchor(self.wall(), 0)
        self._tick()
        while not self.stopping and not self.link.peer_closed:
            if self.takeover_requested:
                self.takeover_requested = False
                self.pilot_takeover()
            if not self._lockstep():
                self._catch_up()
            self._drain()
            if self.end_us is not None and self.t_us >= self.end_us:
                return
            if self._lockstep():
                self._lockstep_step()
            else:
                self._wait(self.pacer.wall_at(self._next_event_us()) - self.wall())

    def _lockstep(self) -> bool:
        """Lockstep holds the plant only while a companion streams setpoints and there is pose
        telemetry for it to answer; otherwise time is paced."""
        return (self.config.lockstep and self.gate.engaged(self.t_us)
                and (self.streams.interval_us(streams.LOCAL_POSITION_NED) > 0
                     or self.streams.interval_us(streams.ATTITUDE) > 0))

    def _catch_up(self) -> None:
        """Paced: run the physics up to the vehicle time that corresponds to now."""
        now = self.wall()
        if self.pacer.behind(now, self.t_us):
            self.pacer.anchor(now, self.t_us)   # stalled (or just left lockstep): do not rush
        target = min(self.pacer.vehicle_us(now), self._next_event_us())
        self._advance_to(target - target % self.dt_us)

    def _lockstep_step(self) -> None:
        now = self.wall()
        self.pacer.anchor(now, self.t_us)
        deadline = self.gate.deadline()
        if deadline is not None:
            if now < deadline:
                self._wait(deadline - now)
                return
            self.gate.expire()
        self._advance_to(self._next_event_us())

    def _next_send_us(self) -> int:
        """Vehicle time of the next message due (a second ahead when nothing is)."""
        candidates = (self.streams.next_due_us(), self.telemetry.next_release_us())
        return min((c for c in candidates if c is not None), default=self.t_us + 1_000_000)

    def _next_event_us(self) -> int:
        """The next physics-grid instant at which something is sent or the run ends."""
        nxt = self._next_send_us()
        if self.end_us is not None:
            nxt = min(nxt, self.end_us)
        nxt = max(nxt, self.t_us + self.dt_us)
        return -(-nxt // self.dt_us) * self.dt_us   # the first step at or after it

    def _advance_to(self, target_us: int) -> None:
        dt, vehicle = self.dt_us * 1e-6, self.vehicle
        nxt = self._next_send_us()
        takeover = self._takeover_us
        while self.t_us < target_us:
            if takeover is not None and self.t_us >= takeover:
                self._takeover_us = takeover = None
                self.pilot_takeover()
            if self._battery_low_us is not None and self.t_us >= self._battery_low_us:
                self._battery_low_us = None
                self.battery_failsafe()
            vehicle.step(dt)
            if vehicle.texts:
                self._flush_texts()
            auto = vehicle.auto
            if auto is not None and (auto.reached or auto.texts
                                     or self.mission.current != self._current_sent):
                self._flush_mission()
            if self.t_us >= nxt:
                self._tick()
                nxt = self._next_send_us()

    def _wait(self, timeout: float) -> None:
        wake_fd = self.wake.fileno() if self.wake is not None else None
        gcs_fd = self.gcs.fd if self.gcs is not None else None
        fds = [fd for fd in (self.link.fd, wake_fd, gcs_fd) if fd is not None]
        timeout = min(max(timeout, 0.0), MAX_WAIT)
        if not fds:
            time.sleep(timeout)
            return
        try:
            ready, _, _ = select.select(fds, [], [], timeout)
        except (OSError, ValueError):
            return
        if wake_fd is not None and self.wake is not None and wake_fd in ready:
            try:
                self.wake.recv(64)
            except OSError:
                pass
        if self.link.fd in ready and not self._drain():
            self.link.check_eof()
        if gcs_fd is not None and gcs_fd in ready:
            self._drain_gcs()

    # --- output -----------------------------------------------------------------------------
    def _tick(self) -> None:
        """Send whatever is due at this instant: heartbeat, status, then pose telemetry."""
        t_us, v, link = self.t_us, self.vehicle, self.link
        if self.mission.home_e7 is None and self.earth.origin_set(t_us):
            self.mission.home_e7 = tuple(e7(d) for d in self.earth.home())  # type: ignore[assignment]
        sample = None
        for mid in self.streams.due(t_us):
            if mid == streams.HEARTBEAT:
                self._heartbeat_now()
            elif mid == streams.SYS_STATUS:
                link.sys_status(link.bad_data, v.setpoints_ignored.get("non-finite", 0),
                                self._status_sensors())
            elif mid == streams.GLOBAL_POSITION_INT:
                self._global_position()
            elif mid == streams.EKF_STATUS_REPORT:
                link.ekf_status(self._ekf_report())
            elif mid == streams.MISSION_CURRENT:
                link._send(link.mav.mission_current_send, self.mission.current)
            elif mid == streams.GPS_RAW_INT:
                self._gps_raw()
            else:
                if sample is None:
                    sample = self._sample()
                self.telemetry.push(t_us, mid, sample)
        sent = False
        for mid, s in self.telemetry.release(t_us):
            (link.attitude if mid == streams.ATTITUDE else link.local_position)(s)
            sent = True
        if sent and self._lockstep():
            self.gate.telemetry_sent(self.wall())

    def _sample(self):
        s = self.vehicle.state
        vx, vy = self.vehicle.velocity()
        north = status.position_offset(self.vehicle.t, self.config.gps_faults)
        return self.telemetry.sample(self.t_us, s.x + north, s.y, s.yaw, vx, vy, s.omega)

    def _ekf_report(self) -> status.EkfReport:
        return status.ekf_report(self.vehicle.t, self.config.ekf_delay, self.config.gps_faults,
                                 self.config.origin.delay)

    def _global_position(self) -> None:
        """GLOBAL_POSITION_INT of the true position (GPS-like: no telemetry faults), once the
        origin is set."""
        if not self.earth.origin_set(self.t_us):
            return
        s = self.vehicle.state
        lat, lon = self.earth.latlon(s.x, s.y)
        vx, vy = self.vehicle.velocity()
        heading = int(round(math.degrees(s.yaw) * 100)) % 36000
        self.link.global_position(self.t_us // 1000, e7(lat), e7(lon),
                                  int(round(self.config.origin.alt * 1000)), vx, vy, heading)

    def _gps_raw(self) -> None:
        """GPS_RAW_INT: the receiver's fix type and accuracy (sitl_plant.status.gps_raw) at
        the true position, once the origin is set (no fix before)."""
        fix, h_acc = status.gps_raw(self.vehicle.t, self.config.gps_faults)
        lat = lon = 0
        if self.earth.origin_set(self.t_us):
            s = self.vehicle.state
            north = status.receiver_offset(self.vehicle.t, self.config.gps_faults)
            lat, lon = (e7(d) for d in self.earth.latlon(s.x + north, s.y))
        else:
            fix, h_acc = status.FIX_NONE, 0
        vx, vy = self.vehicle.velocity()
        self.link.gps_raw(self.t_us, fix, lat, lon, math.hypot(vx, vy),
                          math.degrees(math.atan2(vy, vx)) % 360.0, h_acc)

    def _origin_message(self, msg_id: int) -> None:
        """GPS_GLOBAL_ORIGIN or HOME_POSITION, once the origin is set (else nothing, as
        ArduPilot before its EKF has an origin)."""
        earth, t_us = self.earth, self.t_us
        if not earth.origin_set(t_us):
            return
        alt_mm = int(round(earth.config.alt * 1000))
        if msg_id == streams.GPS_GLOBAL_ORIGIN:
            self.link.gps_global_origin(e7(earth.config.lat), e7(earth.config.lon), alt_mm, t_us)
        else:
            lat, lon = earth.home()
            self.link.home_position(e7(lat), e7(lon), alt_mm, *earth.home_xy, t_us)

    def _links(self) -> list[Link]:
        """The vehicle's link and, with --gcs, the ground station's."""
        return [self.link] + ([self.gcs] if self.gcs is not None else [])

    def _heartbeat_now(self) -> None:
        """A heartbeat on every link at once (a mode change is heard without waiting)."""
        v = self.vehicle
        for link in self._links():
            link.heartbeat(v.autopilot, v.base_mode, v.custom_mode, v.armed)

    def pilot_takeover(self) -> None:
        """A pilot flips the mode switch to HOLD: the vehicle stops following setpoints."""
        v = self.vehicle
        v.set_mode(hold_mode(v.autopilot))
        v.texts.append((SEVERITY_WARNING, "Pilot took over: HOLD"))
        self._flush_texts()
        self._heartbeat_now()

    def battery_failsafe(self) -> None:
        """The battery monitor's low failsafe with its action HOLD, in the order ArduPilot SITL
        sends it (docs/field-faults.md): the HOLD heartbeat, then the text, then SYS_STATUS
        with the battery bit unhealthy."""
        v = self.vehicle
        self.battery_ok = False
        v.set_mode(hold_mode(v.autopilot))
        self._heartbeat_now()
        v.texts.append((SEVERITY_WARNING, v.autopilot.plant.battery_text or "Battery low"))
        self._flush_texts()
        for link in self._links():
            link.sys_status(link.bad_data, v.setpoints_ignored.get("non-finite", 0),
                            self._status_sensors())

    def _flush_mission(self) -> None:
        """AUTO's news to both links: items reached, its texts, the current item if it moved."""
        reached, texts = self.vehicle.auto.pop()
        for link in self._links():
            for seq in reached:
                link._send(link.mav.mission_item_reached_send, seq)
            for severity, text in texts:
                link.statustext(severity, text)
            if self.mission.current != self._current_sent:
                link._send(link.mav.mission_current_send, self.mission.current)
        self._current_sent = self.mission.current

    def _flush_texts(self) -> None:
        for severity, text in self.vehicle.pop_texts():
            self.link.statustext(severity, text)
            if self.gcs is not None and self.gcs is not self.link:
                self.gcs.statustext(severity, text)

    # --- input ------------------------------------------------------------------------------
    def _drain(self) -> int:
        """Handle every message waiting; returns how many were read (garbage included)."""
        n = 0
        if self.gcs is not None:
            self._drain_gcs()
        while True:
            msg = self.link.recv()
            if msg is None:
                return n
            n += 1
            if self.gcs is not None and self._routed(msg):
                self._forward(msg, self.gcs)
            try:
                self._handle(msg)
            except Exception:             # noqa: BLE001 - no input may stop the vehicle
                self.link.bad_data += 1   # a well-formed frame with nonsense in it
                self.handler_errors += 1  # (a bug to fix: the fuzz test asserts none)
            if self.vehicle.texts:
                self._flush_texts()

    def _routed(self, msg: Any) -> bool:
        """Whether a message goes on to the other link: all but what is for the plant alone."""
        if msg.get_type() == "BAD_DATA":
            return False
        target = getattr(msg, "target_system", None)
        if target is None or target == 0:
            return True
        return (target != self.config.sysid
                or getattr(msg, "target_component", 0) not in (0, self.config.compid))

    @staticmethod
    def _forward(msg: Any, to: Link) -> None:
        try:
            to.conn.write(msg.get_msgbuf())
        except OSError:
            pass   # like a radio link

    def _drain_gcs(self) -> None:
        """The ground station's link: route, then answer what is for the plant on that link."""
        gcs = self.gcs
        assert gcs is not None   # drained only when --gcs gave one
        while (msg := gcs.recv()) is not None:
            if msg.get_type() == "BAD_DATA":
                continue
            if self._routed(msg):
                self._forward(msg, self.link)
            target = getattr(msg, "target_system", None)
            if target is None or (target == 0 and msg.get_type() == "HEARTBEAT"):
                continue
            saved, self.link = self.link, gcs    # replies go back where the request came from
            try:
                self._handle(msg)
            except Exception:             # noqa: BLE001 - no input may stop the vehicle
                self.handler_errors += 1
            finally:
                self.link = saved
            if self.vehicle.texts:
                self._flush_texts()

    def _for_us(self, msg: Any) -> bool:
        ours = getattr(msg, "target_system", 0) in (0, self.config.sysid)
        if not ours:
            self.foreign += 1
        return ours

    def _handle(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            if self._for_us(msg):
                self.gate.setpoint_arrived(self.t_us)
                self.vehicle.setpoint(Setpoint(
                    msg.coordinate_frame, msg.type_mask, msg.x, msg.y, msg.vx, msg.vy,
                    msg.afx, msg.afy, msg.yaw, msg.yaw_rate))
        elif kind in ("COMMAND_LONG", "COMMAND_INT"):
            if self._for_us(msg) and msg.target_component in (0, self.config.compid):
                result = self._command(msg)
                self._flush_texts()   # the reason first, then the ACK, as ArduPilot does
                self.link.ack(msg.command, int(result), msg.get_srcSystem(),
                              msg.get_srcComponent())
                while self._after_ack:     # a requested message follows its ACK, as in ArduPilot
                    self._after_ack.pop(0)()
        elif kind in ("PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET"):
            if self._for_us(msg) and self.params.handle(msg, self.link.param_value):
                self._update_mav_type()
        elif kind.startswith("MISSION_"):
            if self._for_us(msg) and getattr(msg, "target_component", 0) in (0, self.config.compid):
                link = self.link
                self.mission.handle(msg, link.mav, lambda fn: lambda *a: link._send(fn, *a))
        elif kind == "SET_MODE":
            if self._for_us(msg):
                if msg.base_mode & FLAG_CUSTOM_MODE_ENABLED:
                    result = self.vehicle.set_mode(msg.custom_mode)
                else:
                    result = Result.FAILED
                self._flush_texts()
                self.link.ack(MSG_ID_SET_MODE, int(result), msg.get_srcSystem(),
                              msg.get_srcComponent())

    def _command(self, msg: Any) -> Result:
        cmd, p1, p2, p3 = msg.command, msg.param1, msg.param2, msg.param3
        v = self.vehicle
        if cmd == MAV_CMD_DO_SET_MODE:
            if not (math.isfinite(p1) and int(p1) & FLAG_CUSTOM_MODE_ENABLED):
                return Result.FAILED
            return v.set_mode(v.autopilot.requested_mode(p2, p3))
        if cmd == MAV_CMD_COMPONENT_ARM_DISARM:
            if p1 not in (0.0, 1.0):
                return Result.UNSUPPORTED
            return v.arm(p1 == 1.0)
        if cmd == MAV_CMD_SET_MESSAGE_INTERVAL:
            reply = self.streams.request(p1, p2, self.t_us)
            if reply.text:
                self.link.statustext(SEVERITY_WARNING, reply.text)
            return Result(reply.result)
        if cmd == MAV_CMD_GET_MESSAGE_INTERVAL:
            if not (math.isfinite(p1) and 0 <= p1 <= 0xFFFF):
                return Result.FAILED
            self.link.message_interval(int(p1), self.streams.interval_us(int(p1)))
            return Result.ACCEPTED
        if cmd == MAV_CMD_REQUEST_MESSAGE:
            return self._send_once(p1)
        if cmd == status.MAV_CMD_RUN_PREARM_CHECKS:
            if not v.armed and v.t < v.config.arm_delay:
                self.link.statustext(SEVERITY_WARNING, status.PREARM_TEXT)
            return Result.ACCEPTED
        return Result.UNSUPPORTED

    def _send_once(self, msg_id: float) -> Result:
        """MAV_CMD_REQUEST_MESSAGE: one copy; a pose goes through the same noise, latency and
        dropout as the streams (it leaves at the next physics step at the earliest)."""
        v, link = self.vehicle, self.link
        if msg_id == streams.HEARTBEAT:
            link.heartbeat(v.autopilot, v.base_mode, v.custom_mode, v.armed)
        elif msg_id == streams.SYS_STATUS:
            link.sys_status(link.bad_data, v.setpoints_ignored.get("non-finite", 0),
                            self._status_sensors())
        elif msg_id in (streams.ATTITUDE, streams.LOCAL_POSITION_NED):
            self.telemetry.push(self.t_us, int(msg_id), self._sample())
        elif msg_id == status.MSG_EKF_STATUS_REPORT:
            report = self._ekf_report()
            self._after_ack.append(lambda: link.ekf_status(report))
        elif msg_id == streams.GLOBAL_POSITION_INT:
            self._global_position()
        elif msg_id in (streams.GPS_GLOBAL_ORIGIN, streams.HOME_POSITION):
            self._after_ack.append(lambda: self._origin_message(int(msg_id)))
        else:
            return Result.DENIED
        return Result.ACCEPTED
