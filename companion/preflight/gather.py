"""Read what the preflight checks need from a live vehicle, and set parameters (--fix).

In order, on one :class:`~companion.live.link.Link`: the vehicle's heartbeat; every parameter
(:class:`~companion.live.params.ParamClient`); SYS_STATUS, the estimator's status (the profile's
``estimator_messages``: EKF_STATUS_REPORT, PX4's ESTIMATOR_STATUS too) and GPS_GLOBAL_ORIGIN
asked for with MAV_CMD_REQUEST_MESSAGE, and the pre-arm messages with MAV_CMD_RUN_PREARM_CHECKS
where the profile says the autopilot answers it (ArduPilot); then the pose streams asked for at the loop's
rate (MAV_CMD_SET_MESSAGE_INTERVAL), measured on the vehicle's clock for a while, and handed back
to their default rate (interval 0). Nothing here arms, changes mode or sends a setpoint.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from ..errors import UserError
from ..live.link import Link, LinkConfig, mavlink
from ..live.origin import from_message
from ..live.params import Param, ParamClient
from .checks import Ekf, Limits, Observed, Streams

POSE = {"LOCAL_POSITION_NED": mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
        "ATTITUDE": mavlink.MAVLINK_MSG_ID_ATTITUDE}
MSG_SYS_STATUS = mavlink.MAVLINK_MSG_ID_SYS_STATUS
MSG_ORIGIN = mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN
MAV_CMD_RUN_PREARM_CHECKS = 401
SETTLE_S = 0.3


@dataclass(frozen=True)
class GatherConfig:
    rate_hz: float = 40.0          # pose telemetry rate to ask for
    measure_s: float = 2.0         # wall s of pose telemetry to measure
    status_timeout: float = 3.0    # wall s to wait for the status messages
    param_timeout: float = 60.0    # wall s for the whole parameter list


@dataclass
class Seen:
    """Everything the vehicle said besides parameters, as it arrived."""
    mavlink_version: int | None = None
    signed: bool = False
    latest: dict[str, Any] = field(default_factory=dict)
    texts: list[str] = field(default_factory=list)


class Probe:
    def __init__(self, link: Link):
        self.link = link
        self.seen = Seen()
        self.client = ParamClient(link, observe=self.observe)
        self.params: dict[str, Param] = {}
        self.prearm_texts: tuple[str, ...] = ()

    def observe(self, msg: Any) -> None:
        """Note a message from the vehicle (any component: the EKF and the autopilot share
        the system id, and ArduPilot sends everything from component 1)."""
        v = self.link.vehicle
        if msg.get_srcSystem() != v.sysid:
            return
        buf = msg.get_msgbuf()
        if buf:
            self.seen.mavlink_version = 2 if buf[0] == 0xFD else 1
            # the frame's incompat flags say "signed" whether or not we hold the key
            # (pymavlink's get_signed() is true only for a verified signature)
            if buf[0] == 0xFD and len(buf) > 2 and buf[2] & 0x01:
                self.seen.signed = True
        kind = msg.get_type()
        self.seen.latest[kind] = msg
        if kind == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode("ascii", "replace")
            self.seen.texts.append(text.rstrip("\x00"))

    def pump(self, seconds: float, done=lambda: False) -> None:
        """Read and note messages for ``seconds`` (or until ``done()``)."""
        deadline = time.monotonic() + seconds
        while not done() and (left := deadline - time.monotonic()) > 0:
            msg = self.link.recv()
            if msg is None:
                self.link.wait(min(left, 0.05))
            elif msg.get_type() != "BAD_DATA":
                self.observe(msg)

    # --- the steps ----------------------------------------------------------------------------
    def read_params(self, timeout: float) -> dict[str, Param]:
        self.params = self.client.fetch_all(timeout=timeout)
        if not self.params:
            v = self.link.vehicle
            if self.seen.signed and self.link.config.signing_key is None:
                raise UserError(f"system {v.sysid} signs its messages and did not answer the "
                                "companion's unsigned parameter requests: give --signing-key")
            raise UserError(f"system {v.sysid} did not answer PARAM_REQUEST_LIST (asked "
                            "repeatedly): the parameters could not be read")
        return self.params

    def read_status(self, timeout: float) -> None:
        """SYS_STATUS, the estimator's status and the EKF origin, each asked for once a second
        until it arrives or ``timeout`` passes; the pre-arm messages when disarmed (where the
        autopilot answers MAV_CMD_RUN_PREARM_CHECKS)."""
        link, seen = self.link, self.seen
        facts = link.vehicle.profile.preflight
        estimators = facts.estimator_messages
        wanted = {"SYS_STATUS": MSG_SYS_STATUS, "GPS_GLOBAL_ORIGIN": MSG_ORIGIN}
        wanted.update((k, getattr(mavlink, f"MAVLINK_MSG_ID_{k}")) for k in estimators)
        before = {k: seen.latest.get(k) for k in wanted}
        if facts.prearm_command and not link.armed:
            link.command(MAV_CMD_RUN_PREARM_CHECKS)
        deadline = time.monotonic() + timeout
        texts_at = len(seen.texts)

        def fresh(kind: str) -> bool:
            return seen.latest.get(kind) is not None and seen.latest.get(kind) is not before[kind]

        def estimator_done() -> bool:
            return any(fresh(k) for k in estimators)

        while time.monotonic() < deadline:
            pending = [k for k in wanted if not fresh(k)
                       and not (k in estimators and estimator_done())]
            if not pending:
                break
            for kind in pending:
                link.command(mavlink.MAV_CMD_REQUEST_MESSAGE, wanted[kind])
            self.pump(min(1.0, deadline - time.monotonic()),
                      done=lambda pending=pending: all(fresh(k) for k in pending))
        # the pre-arm messages follow the command's ACK: give them a moment
        if facts.prearm_command and not link.armed:
            self.pump(0.5)
        self.prearm_texts = tuple(t for t in seen.texts[texts_at:]
                                  if t.lower().startswith(("prearm", "arm:")))
        self.prearm_texts += tuple(t for t in seen.texts[:texts_at]
                                   if t.lower().startswith("prearm"))

    def measure_streams(self, rate_hz: float, seconds: float) -> Streams:
        """Ask for the pose messages at ``rate_hz``, measure them on the vehicle's clock, then
        give them back their default rate."""
        link = self.link
        before = {mid: self._interval_us(mid) for mid in POSE.values()}
        results = {name: link.set_message_rate(mid, rate_hz) for name, mid in POSE.items()}
        stamps: dict[str, list[int]] = {name: [] for name in POSE}
        start = time.monotonic()
        settle = start + min(SETTLE_S, seconds / 4)   # before it: the old rate's last messages
        deadline = start + seconds
        while (left := deadline - time.monotonic()) > 0:
            msg = link.recv()
            if msg is None:
                link.wait(min(left, 0.05))
                continue
            kind = msg.get_type()
            if kind == "BAD_DATA":
                continue
            self.observe(msg)
            if kind in stamps and link.is_vehicle(msg) and time.monotonic() >= settle:
                stamps[kind].append(int(msg.time_boot_ms))
        for mid, interval in before.items():   # as they were (unknown: the default, 0)
            link.command_wait(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mid,
                              interval if interval is not None and interval != 0 else 0)
        return Streams(rate_hz, results, {k: _rate(v) for k, v in stamps.items()})

    def _interval_us(self, msg_id: int, timeout: float = 1.0) -> int | None:
        """The link's interval for ``msg_id`` (MAV_CMD_GET_MESSAGE_INTERVAL; -1 disabled), so
        a companion already streaming on this link gets its rate back; None: no answer."""
        old = self.seen.latest.get("MESSAGE_INTERVAL")
        self.link.command(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, msg_id)

        def answered() -> bool:
            m = self.seen.latest.get("MESSAGE_INTERVAL")
            return m is not None and m is not old and m.message_id == msg_id
        self.pump(timeout, done=answered)
        return int(self.seen.latest["MESSAGE_INTERVAL"].interval_us) if answered() else None

    def observed(self, streams: Streams | None, signing_key: bool, serial: bool,
                 limits: Limits | None) -> Observed:
        v, seen, link = self.link.vehicle, self.seen, self.link
        sys_status = seen.latest.get("SYS_STATUS")
        ekf_msg = seen.latest.get("EKF_STATUS_REPORT") or seen.latest.get("ESTIMATOR_STATUS")
        ekf = None
        if ekf_msg is not None and ekf_msg.get_type() == "EKF_STATUS_REPORT":
            ekf = Ekf(int(ekf_msg.flags), ekf_msg.velocity_variance,
                      ekf_msg.pos_horiz_variance, ekf_msg.pos_vert_variance,
                      ekf_msg.compass_variance)
        elif ekf_msg is not None:        # ESTIMATOR_STATUS: test ratios, the same flag bits
            ekf = Ekf(int(ekf_msg.flags), ekf_msg.vel_ratio, ekf_msg.pos_horiz_ratio,
                      ekf_msg.pos_vert_ratio, ekf_msg.mag_ratio)
        origin_msg = seen.latest.get("GPS_GLOBAL_ORIGIN")
        origin = None if origin_msg is None else from_message(origin_msg)   # 0, 0: not set
        return Observed(
            autopilot=v.autopilot, mav_type=v.mav_type, modes=frozenset(link.mode_names()),
            armed=link.armed, mavlink_version=seen.mavlink_version or 2, signed=seen.signed,
            signing_key=signing_key, serial=serial,
            companion_sysid=link.source_system, vehicle_sysid=v.sysid,
            params={name: p.value for name, p in self.params.items()},
            sensors=None if sys_status is None else (
                int(sys_status.onboard_control_sensors_present),
                int(sys_status.onboard_control_sensors_enabled),
                int(sys_status.onboard_control_sensors_health)),
            prearm_texts=self.prearm_texts,
            ekf=ekf,
            origin=None if origin is None else origin.latlon,
            streams=streams, limits=limits)

    def set_params(self, values: dict[str, float]) -> list[dict[str, Any]]:
        """PARAM_SET each, then read each back by name; one report row per parameter."""
        rows = []
        for name, value in values.items():
            old = self.params[name]
            echo = self.client.set(name, value, old.type)
            back = self.client.read([name]).get(name) or echo
            if back is not None:
                self.params[name] = Param(name, back.value, back.type, old.index)
            rows.append({"name": name, "from": old.value, "to": value,
                         "read_back": None if back is None else back.value,
                         "ok": back is not None and back.value == value})
        return rows


def _rate(stamps: list[int]) -> float | None:
    """Messages per second of vehicle time (None: fewer than two arrived)."""
    distinct = sorted(set(stamps))
    if len(distinct) < 2 or distinct[-1] == distinct[0]:
        return None
    return (len(distinct) - 1) * 1000.0 / (distinct[-1] - distinct[0])


def connect(config: LinkConfig) -> tuple[Link, Probe]:
    """Open the link and wait for the vehicle (UserError, exit 2, when there is none)."""
    link = Link(config)
    try:
        link.wait_vehicle()
        link.send_heartbeat()
    except UserError as err:
        refused = link.signing_rejected
        link.close()
        if refused:
            raise UserError(f"{err}; {refused} frames arrived unsigned or signed with another "
                            "key: check --signing-key") from None
        raise
    except BaseException:
        link.close()
        raise
    return link, Probe(link)
