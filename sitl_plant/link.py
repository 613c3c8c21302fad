"""The plant's MAVLink endpoint: pymavlink's connection, and the messages an ArduPilot Rover sends.

MAVLink 2 (MAVLINK20 is set before pymavlink is imported), dialect ardupilotmega, any mavutil
connection string. Never raises on a bad peer: receive errors and garbage are counted, send errors
are dropped (like a radio link).
"""

from __future__ import annotations

import os
import socket
import struct
from typing import Any

from companion.profiles.autopilot import AutopilotProfile

from .telemetry import PoseSample

MAV_TYPE_GROUND_ROVER = 10
MAV_STATE_STANDBY = 3
MAV_STATE_ACTIVE = 4


class LinkError(Exception):
    """The connection string cannot be opened (a user error)."""


def _mavutil():
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil
    return mavutil


class Link:
    def __init__(self, url: str, sysid: int, compid: int, signing_key: bytes | None = None,
                 mavlink1: bool = False):
        _mavutil()
        from companion.errors import UserError
        from companion.mav.connection import open_connection
        try:   # a URL, or a serial device (DEVICE or DEVICE,BAUD: a pty in the tests)
            self.conn = open_connection(url, source_system=sysid, source_component=compid,
                                        dialect="ardupilotmega")
        except UserError as exc:
            raise LinkError(str(exc)) from None
        self.mav = self.conn.mav
        from companion.mav import signing
        from companion.mav.sockets import size_receive_buffer
        self.recv_buffer = size_receive_buffer(self.conn)   # bursts of setpoints / commands
        self.signing = signing_key is not None
        if signing_key is not None:
            # Signed out; unsigned, wrong-key and replayed commands and setpoints are refused
            # by pymavlink (BAD_DATA, counted in bad_data and signing_rejected).
            signing.enable(self.conn, signing_key)
        self.bad_data = 0
        self.received = 0
        self.peer_closed = False
        self.mav_type = MAV_TYPE_GROUND_ROVER   # the heartbeat's (the server may change it)
        if mavlink1:
            # A port set to MAVLink 1 (SERIALn_PROTOCOL 1): send v1 frames, still read both.
            send = self.mav.send
            self.mav.send = lambda msg, force_mavlink1=False: send(msg, force_mavlink1=True)

    @property
    def signing_rejected(self) -> int:
        return int(self.mav.signing.reject_count) if self.signing else 0

    @property
    def fd(self) -> int | None:
        return getattr(self.conn, "fd", None)

    def recv(self) -> Any | None:
        """One parsed message, or None when nothing (more) is waiting. Garbage is counted."""
        try:
            msg = self.conn.recv_msg()
        except OSError:
            return None
        if msg is None:
            return None
        if msg.get_type() == "BAD_DATA":
            self.bad_data += 1
            return msg
        self.received += 1
        return msg

    def check_eof(self) -> None:
        """Called when the descriptor polled readable but no message came: a TCP peer may have
        hung up, which pymavlink does not notice (the descriptor would stay readable forever).
        ``tcpin`` goes back to listening for the next client; ``tcp`` sets :attr:`peer_closed`."""
        port = getattr(self.conn, "port", None)
        if not isinstance(port, socket.socket) or port.type != socket.SOCK_STREAM:
            return
        try:
            at_eof = port.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
        except BlockingIOError:
            return
        except OSError:
            at_eof = True
        if not at_eof:
            return
        listen = getattr(self.conn, "listen", None)
        if isinstance(listen, socket.socket):
            port.close()
            self.conn.port = None
            self.conn.fd = listen.fileno()
        else:
            self.peer_closed = True

    def _send(self, fn, *args) -> None:
        try:
            fn(*args)
        except (OSError, struct.error):
            pass  # like a radio link: the next message may get through

    def heartbeat(self, autopilot: AutopilotProfile, base_mode: int, custom_mode: int,
                  armed: bool) -> None:
        state = MAV_STATE_ACTIVE if armed else MAV_STATE_STANDBY
        self._send(self.mav.heartbeat_send, self.mav_type, autopilot.mav_autopilot[0], base_mode,
                   custom_mode, state)

    def sys_status(self, receive_errors: int, setpoints_nonfinite: int,
                   sensors: tuple[int, int, int] = (0, 0, 0)) -> None:
        self._send(self.mav.sys_status_send, *sensors, 0, 12600, -1, -1, 0,
                   min(receive_errors, 0xFFFF), min(setpoints_nonfinite, 0xFFFF), 0, 0, 0)

    def attitude(self, s: PoseSample) -> None:
        self._send(self.mav.attitude_send, s.time_boot_ms, 0.0, 0.0, s.yaw, 0.0, 0.0, s.yaw_rate)

    def local_position(self, s: PoseSample) -> None:
        self._send(self.mav.local_position_ned_send, s.time_boot_ms, s.x, s.y, 0.0, s.vx, s.vy, 0.0)

    def gps_global_origin(self, lat_e7: int, lon_e7: int, alt_mm: int, time_usec: int) -> None:
        self._send(self.mav.gps_global_origin_send, lat_e7, lon_e7, alt_mm, time_usec)

    def home_position(self, lat_e7: int, lon_e7: int, alt_mm: int, x: float, y: float,
                      time_usec: int) -> None:
        self._send(self.mav.home_position_send, lat_e7, lon_e7, alt_mm, x, y, 0.0,
                   [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, time_usec)

    def global_position(self, time_boot_ms: int, lat_e7: int, lon_e7: int, alt_mm: int,
                        vx: float, vy: float, heading_cdeg: int) -> None:
        self._send(self.mav.global_position_int_send, time_boot_ms, lat_e7, lon_e7, alt_mm, 0,
                   int(round(vx * 100)), int(round(vy * 100)), 0, heading_cdeg)

    def gps_raw(self, time_usec: int, fix_type: int, lat_e7: int, lon_e7: int, speed: float,
                course_deg: float, h_acc_mm: int) -> None:
        self._send(self.mav.gps_raw_int_send, time_usec, fix_type, lat_e7, lon_e7, 0, 80, 120,
                   int(round(speed * 100)), int(round(course_deg * 100)) % 36000, 20, 0,
                   h_acc_mm, 2 * h_acc_mm, 50, 0)

    def statustext(self, severity: int, text: str) -> None:
        self._send(self.mav.statustext_send, severity, text.encode("ascii", "replace")[:50])

    def ack(self, command: int, result: int, to_system: int, to_component: int) -> None:
        self._send(self.mav.command_ack_send, command, result, 0, 0, to_system, to_component)

    def message_interval(self, msg_id: int, interval_us: int) -> None:
        self._send(self.mav.message_interval_send, msg_id, interval_us)

    def param_value(self, name: str, value: float, param_type: int, count: int,
                    index: int) -> None:
        self._send(self.mav.param_value_send, name.encode("ascii"), value, param_type, count,
                   index)

    def ekf_status(self, r) -> None:
        """EKF_STATUS_REPORT from a :class:`sitl_plant.status.EkfReport`."""
        self._send(self.mav.ekf_status_report_send, r.flags, r.velocity_variance,
                   r.pos_horiz_variance, r.pos_vert_variance, r.compass_variance, 0.0)

    def close(self) -> None:
        try:
            self.conn.close()
        except OSError:
            pass
