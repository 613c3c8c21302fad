"""The MAVLink connection to one vehicle: pymavlink underneath, the companion's vocabulary on top.

Connect, wait for the vehicle's heartbeat and pick its autopilot's profile
(:mod:`companion.profiles`), ask for pose telemetry at a rate (reading the COMMAND_ACKs and
falling back to a rate the vehicle accepts), change mode, arm, and encode the tracker's command
as SET_POSITION_TARGET_LOCAL_NED. What differs between autopilots is the profile's: the mode
table (names as pymavlink gives them), how DO_SET_MODE asks for a mode, and the setpoint
encoding (:class:`~companion.profiles.setpoint.SetpointEncoding`, its frame, type mask and
``encode``: ArduPilot's speed and yaw rate in BODY_NED, Rover's
``set_desired_turn_rate_and_speed``, the paper's two inputs; PX4's velocity vector u_p in
LOCAL_NED, along which PX4 rovers steer themselves).

Each setpoint carries the ``time_boot_ms`` of the telemetry sample it answers (ArduPilot and PX4
ignore the field), so a log or a test can pair every setpoint with its sample.

``LinkConfig.signing_key`` turns on MAVLink 2 signing (:mod:`companion.mav.signing`: outgoing
signed, unsigned / wrong-key / replayed input refused and counted) and ``LinkConfig.tlog``
records a .tlog of both directions (:mod:`companion.live.flightlog`), both through pymavlink's own
support. A TCP connection the vehicle closes (a reboot, a serial-to-TCP bridge restarting) is
reopened, at most one try a second (:meth:`Link.recv`; pymavlink's own reconnect would block the
loop and print to stdout). A UDP socket gets a large receive buffer (:mod:`companion.mav.sockets`: the kernel's default holds
about 256 small datagrams, and a burst beyond it is dropped silently).
"""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

os.environ["MAVLINK20"] = "1"   # before pymavlink.mavutil is imported: MAVLink 2 frames
# Every connection here says dialect="ardupilotmega"; without this mavutil would first load
# its default "all" dialect too (about 7 MB resident that nothing uses).
os.environ.setdefault("MAVLINK_DIALECT", "ardupilotmega")
from pymavlink import mavutil  # noqa: E402

from .. import profiles  # noqa: E402
from ..core.signals import Command  # noqa: E402
from ..errors import UserError  # noqa: E402
from ..mav import signing  # noqa: E402
from ..mav.connection import open_connection  # noqa: E402
from ..mav.sockets import size_receive_buffer  # noqa: E402
from ..profiles.autopilot import AutopilotProfile, ModeTable  # noqa: E402
from ..profiles.setpoint import SetpointEncoding  # noqa: E402
from .config import PLACEHOLDER_SYSID, LinkConfig  # noqa: E402,F401  (its home; imported from here too)

mavlink = mavutil.mavlink

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
# Rates to fall back to, fastest first, when the vehicle refuses the one asked for.
FALLBACK_RATES = (1000.0, 800.0, 500.0, 400.0, 250.0, 200.0, 100.0, 50.0, 40.0, 25.0, 20.0,
                  10.0, 5.0, 2.0, 1.0)


@dataclass(frozen=True)
class VehicleInfo:
    sysid: int
    compid: int
    profile: AutopilotProfile      # from the first heartbeat's autopilot field
    mav_type: int

    @property
    def autopilot(self) -> str:
        """The autopilot's name ("ardupilot", "px4"): for logs and JSON."""
        return self.profile.name


class Link:
    """One pymavlink connection, following one vehicle."""

    def __init__(self, config: LinkConfig):
        self.config = config
        # A URL or a serial device (DEVICE[,BAUD] or config.baud); one-line UserError if not.
        self.master = open_connection(
            config.url, baud=config.baud,
            source_system=(PLACEHOLDER_SYSID if config.source_system is None
                           else config.source_system),
            source_component=config.source_component, dialect="ardupilotmega")
        self.mav = self.master.mav
        self.recv_buffer = size_receive_buffer(self.master)
        if config.signing_key is not None:
            signing.enable(self.master, config.signing_key)
        self.tlog = None
        # Called before every sleep of the loop: the flight logs flush there (crash safety).
        self.on_idle: list[Callable[[], None]] = []
        if config.tlog is not None:
            from .flightlog import open_tlog
            self.tlog = open_tlog(config.tlog)
            self.tlog.attach(self.master)
            self.on_idle.append(self.tlog.idle)
        self._vehicle: VehicleInfo | None = None   # found by wait_vehicle (see vehicle)
        # Mode and arming as the vehicle's own heartbeats say (is_vehicle_heartbeat), not
        # pymavlink's per-system state, which any frame carrying our vehicle's system id
        # rewrites (a stranger's heartbeat, a corrupted one claiming another vehicle type).
        self._mode = ""
        self._armed = False
        self._modes = ModeTable()                 # the vehicle's, from its profile and MAV_TYPE
        # the setpoint encoding, from the profile (see send_command)
        self._setpoint: SetpointEncoding | None = None
        self.setpoints_sent = 0
        self._recv_failed = False                 # the last read raised (see wait)
        self.last_ack: dict[int, int] = {}        # command id -> last result
        self.log: Callable[[str], None] = lambda text: None   # the session's, once it runs
        self.reconnects = 0                       # TCP connections reopened
        self._dropped = False                     # the TCP peer closed the connection
        self._next_reopen = 0.0                   # monotonic s
        if isinstance(self.master, mavutil.mavtcp):
            # pymavlink calls these on EOF / reset (and would print, then reconnect blocking)
            self.master.handle_eof = self.master.handle_disconnect = self._tcp_dropped

    def linger(self, seconds: float) -> None:
        """Keep reading (and dropping) for ``seconds`` before closing, so what was just sent
        gets through and what arrives meanwhile is still read (and counted)."""
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            if self.recv() is None:      # (not self.wait: the sinks' idle hooks are closed)
                if self._recv_failed:
                    time.sleep(min(left, 0.02))
                else:
                    self.master.select(min(left, 0.02))

    def close(self) -> None:
        try:
            self.master.close()
        except OSError:
            pass
        if self.tlog is not None:
            self.tlog.close()

    @property
    def vehicle(self) -> VehicleInfo:
        """The vehicle followed, once :meth:`wait_vehicle` has found it (reading it before is a
        programming error)."""
        if self._vehicle is None:
            raise RuntimeError("Link.vehicle read before wait_vehicle() found a vehicle")
        return self._vehicle

    @property
    def found(self) -> VehicleInfo | None:
        """The vehicle, or None while :meth:`wait_vehicle` has not found one yet."""
        return self._vehicle

    @property
    def signing_rejected(self) -> int:
        """Incoming frames refused for their signature (0 without signing)."""
        return signing.rejected(self.master) if self.config.signing_key is not None else 0

    # --- receiving ----------------------------------------------------------------------------
    def last_heard(self, kind: str) -> Any | None:
        """The last ``kind`` message the followed vehicle's system sent, read by anything
        before now (the setup's command waits too): pymavlink keeps one per system."""
        state = self.master.sysid_state.get(self.vehicle.sysid)
        return None if state is None else state.messages.get(kind)

    def _tcp_dropped(self) -> None:
        if not self._dropped:
            self.log(f"the vehicle closed the TCP connection {self.config.url}; reopening it")
        self._dropped = True

    def _reopen(self) -> None:
        """One try at reopening a dropped TCP connection (blocks at most 0.2 s)."""
        self._next_reopen = time.monotonic() + 1.0
        m = self.master
        try:
            sock = socket.create_connection(m.destination_addr, timeout=0.2)
        except OSError:
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        try:
            m.port.close()
        except OSError:
            pass
        m.port, m.fd = sock, sock.fileno()
        self._dropped = False
        self.reconnects += 1
        self.log(f"TCP connection {self.config.url} reopened")

    def recv(self) -> Any | None:
        """One parsed message, or None when nothing is waiting. Never blocks, never raises."""
        if self._dropped:
            if time.monotonic() >= self._next_reopen:
                self._reopen()
            if self._dropped:
                return None
        try:
            msg = self.master.recv_msg()
        except OSError:   # a serial device unplugged or hung up; a UDP peer's ICMP error
            self._recv_failed = True
            return None
        self._recv_failed = False
        if (msg is not None and msg.get_type() == "HEARTBEAT" and self._vehicle is not None
                and self.is_vehicle_heartbeat(msg)):
            self._note_heartbeat(msg)
        return msg

    def _note_heartbeat(self, msg: Any) -> None:
        self._mode = self.vehicle.profile.mode_name(self._modes, msg.base_mode, msg.custom_mode)
        self._armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)

    def wait(self, timeout: float) -> None:
        """Sleep until data arrives or ``timeout`` seconds pass (pymavlink's select)."""
        for hook in self.on_idle:
            hook()
        if timeout > 0 and (self._recv_failed or self._dropped):
            time.sleep(timeout)   # a hung-up device polls readable at once: do not spin on it
        elif timeout > 0:
            self.master.select(timeout)

    def is_vehicle(self, msg: Any) -> bool:
        """True for a message from the vehicle we follow (its system and component)."""
        v = self._vehicle
        return v is not None and msg.get_srcSystem() == v.sysid and msg.get_srcComponent() == v.compid

    def is_for_us(self, msg: Any) -> bool:
        """A COMMAND_ACK (or any targeted message) addressed to us or to everyone: the vehicle
        answers every ground station on the link, and another's ACK is not ours."""
        return (getattr(msg, "target_system", 0) in (0, self.source_system)
                and getattr(msg, "target_component", 0) in (0, self.config.source_component))

    @property
    def source_system(self) -> int:
        """The companion's own system id as sent: ``config.source_system``, else the vehicle's
        (once its heartbeat is known)."""
        return int(self.mav.srcSystem)

    @property
    def source_component(self) -> int:
        return int(self.mav.srcComponent)

    def is_vehicle_heartbeat(self, msg: Any) -> bool:
        """A HEARTBEAT of our vehicle that still says what it said at first (autopilot and
        MAV_TYPE): one claiming to be another kind of vehicle is corrupted or forged, and its
        mode number would be read in another table (pymavlink names modes by type)."""
        v = self.vehicle
        return (self.is_vehicle(msg) and msg.type == v.mav_type
                and msg.autopilot in v.profile.mav_autopilot)

    @property
    def mode(self) -> str:
        """The vehicle's flight mode from its last heartbeat (pymavlink's name)."""
        return self._mode

    @property
    def armed(self) -> bool:
        return self._armed

    # --- connection set-up (blocking; before the control loop) ------------------------------
    def wait_vehicle(self, should_stop: Callable[[], bool] = lambda: False) -> VehicleInfo:
        """Wait for the first heartbeat of a vehicle (of ``config.sysid`` if given)."""
        cfg = self.config
        deadline = time.monotonic() + cfg.heartbeat_timeout
        while time.monotonic() < deadline and not should_stop():
            msg = self.recv()
            if msg is None:
                self.wait(0.05)
                continue
            if msg.get_type() != "HEARTBEAT" or not self.master.probably_vehicle_heartbeat(msg):
                continue
            if cfg.sysid is not None and msg.get_srcSystem() != cfg.sysid:
                continue
            profile = profiles.from_heartbeat(msg.autopilot)
            if profile is None:
                known = " and ".join(p.label for p in profiles.AUTOPILOTS.values())
                raise UserError(f"system {msg.get_srcSystem()} runs an autopilot this companion "
                                f"does not drive (MAV_AUTOPILOT {msg.autopilot}); "
                                f"{known} are supported")
            self._vehicle = VehicleInfo(msg.get_srcSystem(), msg.get_srcComponent(), profile,
                                       msg.type)
            self.master.target_system = self.vehicle.sysid
            self.master.target_component = self.vehicle.compid
            if cfg.source_system is None:
                # The onboard-computer convention: a component of the vehicle's own system.
                self.mav.srcSystem = self.vehicle.sysid
            self._modes = profile.modes_for(msg.type)
            self._setpoint = profile.setpoint
            self._note_heartbeat(msg)
            return self.vehicle
        if should_stop():
            raise KeyboardInterrupt
        which = f"system {cfg.sysid}" if cfg.sysid is not None else "any vehicle"
        raise UserError(f"no heartbeat from {which} on {cfg.url} within "
                        f"{cfg.heartbeat_timeout:g} s: is the vehicle running and sending there?")

    def command(self, command: int, *params: float) -> None:
        """Send a COMMAND_LONG to the vehicle (not waiting for its ACK)."""
        p = list(params) + [0.0] * (7 - len(params))
        self.mav.command_long_send(self.vehicle.sysid, self.vehicle.compid, command, 0, *p)

    def command_wait(self, command: int, *params: float, tries: int = 2) -> int | None:
        """COMMAND_LONG and its COMMAND_ACK result; None if no ACK came (after ``tries`` sends).

        Other messages read meanwhile are dropped: only for set-up, before the control loop.
        """
        for _ in range(tries):
            self.command(command, *params)
            deadline = time.monotonic() + self.config.ack_timeout
            while (left := deadline - time.monotonic()) > 0:
                msg = self.recv()
                if msg is None:
                    self.wait(min(left, 0.05))
                elif (msg.get_type() == "COMMAND_ACK" and msg.command == command
                      and self.is_vehicle(msg) and self.is_for_us(msg)):
                    self.last_ack[command] = msg.result
                    return msg.result
        return None

    def set_message_rate(self, msg_id: int, hz: float) -> int | None:
        """MAV_CMD_SET_MESSAGE_INTERVAL: the ACK's result, or None without an answer."""
        return self.command_wait(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)

    def negotiate_rate(self, hz: float) -> tuple[float | None, list[str]]:
        """Ask for LOCAL_POSITION_NED and ATTITUDE at ``hz``, then at slower rates while refused.

        Returns (accepted rate, notes). ``None`` means the vehicle never answered (an autopilot
        without MAV_CMD_SET_MESSAGE_INTERVAL): the loop then runs at whatever rate arrives.
        """
        notes: list[str] = []
        candidates = [hz] + [r for r in FALLBACK_RATES if r < hz]
        for rate in candidates:
            results = [self.set_message_rate(mid, rate) for mid in
                       (mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, mavlink.MAVLINK_MSG_ID_ATTITUDE)]
            if results == [ACCEPTED, ACCEPTED]:
                return rate, notes
            if results == [None, None]:
                notes.append(f"no COMMAND_ACK for SET_MESSAGE_INTERVAL at {rate:g} Hz: "
                             "using the rate that arrives")
                return None, notes
            notes.append(f"vehicle refused {rate:g} Hz telemetry (COMMAND_ACK results "
                         f"{results}); trying slower")
        raise UserError(f"the vehicle refused pose telemetry at every rate from {hz:g} Hz down "
                        f"to {candidates[-1]:g} Hz")

    # --- commands used inside the control loop (never wait) ---------------------------------
    def request_mode(self, name: str) -> None:
        """MAV_CMD_DO_SET_MODE for a mode name (the profile's mode table for the vehicle's
        MAV_TYPE, chosen once from its first heartbeat; the parameters as the profile says)."""
        mode = self._modes.by_name(name)
        if mode is None:
            raise UserError(f"the vehicle has no mode {name!r}")
        self.command(mavlink.MAV_CMD_DO_SET_MODE, *self.vehicle.profile.set_mode_params(mode))

    def request_message(self, msg_id: int) -> None:
        """MAV_CMD_REQUEST_MESSAGE: the vehicle sends ``msg_id`` once (not waiting for it)."""
        self.command(mavlink.MAV_CMD_REQUEST_MESSAGE, msg_id)

    def mode_names(self) -> set[str]:
        return set(self._modes.names())

    def request_arm(self) -> None:
        self.master.arducopter_arm()   # MAV_CMD_COMPONENT_ARM_DISARM param1 = 1, any vehicle

    def send_heartbeat(self) -> None:
        self.mav.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID,
                                0, 0, mavlink.MAV_STATE_ACTIVE)

    def send_command(self, cmd: Command, time_boot_ms: int) -> None:
        """The tracker's command as SET_POSITION_TARGET_LOCAL_NED (see the module docstring)."""
        v, sp = self.vehicle, self._setpoint
        assert sp is not None          # set with the vehicle (wait_vehicle)
        vx, vy, yaw_rate = sp.encode(cmd)
        self.mav.set_position_target_local_ned_send(
            time_boot_ms, v.sysid, v.compid, sp.frame, sp.type_mask,
            0.0, 0.0, 0.0, vx, vy, 0.0, 0.0, 0.0, 0.0, 0.0, yaw_rate)
        self.setpoints_sent += 1

    def send_stop(self, time_boot_ms: int = 0) -> None:
        """Zero speed and zero turn rate (or the zero velocity vector)."""
        self.send_command(STOP, time_boot_ms)


STOP = Command(0.0, 0.0, 0.0, 0.0)
