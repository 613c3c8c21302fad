"""From a flight log to what the fit sees: setpoints held on the measurement times, the measured
response, and the autopilot (and its parameters) the log recorded.

The log is read by :func:`companion.logs.logread.read` (the companion's CSV or any .tlog). The
response is the signed speed along the heading (``Flight.speed_along``: LOCAL_POSITION_NED
vx cos(yaw) + vy sin(yaw) in a .tlog, the differentiated pose in a CSV) and the turn rate
(ATTITUDE yawspeed, or the differentiated yaw). Each setpoint carries the ``time_boot_ms`` of the
sample it answers, so it is in force from that sample until the next setpoint; the pure delay
the fit finds includes the companion's own reaction time.

The window fitted runs from 1 s before the first setpoint that asks for motion to 3 s after the
last one (the stop): the minutes a vehicle may sit disarmed before a run would otherwise dilute
the RMS. Problems are one-line :class:`~companion.errors.UserError` s (exit 2).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .. import profiles
from ..errors import UserError
from ..profiles.autopilot import AutopilotProfile
from .series import Series

LEAD_IN = 1.0          # s of log kept before the first moving setpoint
LEAD_OUT = 3.0         # s after the last one: the stop is data too
MIN_DURATION = 5.0     # s of window: less cannot show a delay, a lag and a ramp
MIN_SAMPLES = 50


def series_from_flight(flight) -> Series:
    """The fit's :class:`Series` from a :class:`companion.logs.logread.Flight`."""
    name = flight.source
    if flight.cmd_t is None or len(flight.cmd_t) == 0:
        raise UserError(f"LOG {name}: no setpoints in it (SET_POSITION_TARGET_LOCAL_NED answering "
                        "its pose samples): identification needs what the vehicle was asked")
    speed_cmd = np.asarray(flight.speed_cmd, dtype=float)
    yaw_cmd = np.asarray(flight.yaw_rate_cmd, dtype=float)
    course = getattr(flight, "course_cmd", None)
    vector = np.all(np.isnan(yaw_cmd))
    if vector and course is None:
        raise UserError(f"LOG {name}: its setpoints are velocity vectors without a turn rate "
                        "(PX4) and the log is not a .tlog: a PX4 vehicle is identified from "
                        "the .tlog, where the vectors' course is")
    if vector:
        # PX4: speed |u_p| and the course atan2(u_p); the turn rate PX4's course loop makes of
        # it is derived in the fit (series.with_course_loop) on the measured heading
        yaw_cmd = np.asarray(course, dtype=float)
    cmd_t = np.asarray(flight.cmd_t, dtype=float)
    good = np.isfinite(cmd_t) & np.isfinite(speed_cmd) & np.isfinite(yaw_cmd)
    cmd_t, speed_cmd, yaw_cmd = cmd_t[good], speed_cmd[good], yaw_cmd[good]
    moving = np.flatnonzero((speed_cmd != 0.0) | ((yaw_cmd != 0.0) & (not vector)))
    if len(moving) == 0:
        raise UserError(f"LOG {name}: every setpoint in it is zero: nothing to identify")
    along = flight.speed_along if flight.speed_along is not None else flight.speed
    t = np.asarray(flight.t, dtype=float)
    keep = ((t >= cmd_t[moving[0]] - LEAD_IN) & (t <= cmd_t[moving[-1]] + LEAD_OUT)
            & np.isfinite(along) & np.isfinite(flight.yaw_rate))
    speed = np.asarray(along, dtype=float)[keep]
    rate = np.asarray(flight.yaw_rate, dtype=float)[keep]
    yaw = np.asarray(flight.yaw, dtype=float)[keep]
    t = t[keep]
    if len(t) < MIN_SAMPLES or t[-1] - t[0] < MIN_DURATION:
        span = float(t[-1] - t[0]) if len(t) else 0.0
        raise UserError(f"LOG {name}: too short to identify: {len(t)} samples over {span:.1f} s "
                        f"of setpoints (need {MIN_SAMPLES} over {MIN_DURATION:g} s)")
    # The setpoint in force at each sample: the latest one answering a sample at or before it.
    k = np.searchsorted(cmd_t, t, side="right") - 1
    held = k >= 0
    u = np.where(held, speed_cmd[np.maximum(k, 0)], 0.0)
    w = np.where(held, yaw_cmd[np.maximum(k, 0)], 0.0)
    if vector:
        # the turn-rate command is derived later; the course and the heading go along
        return Series(t, u, np.zeros_like(u), speed, rate, course_cmd=np.where(held, w, yaw),
                      yaw=yaw)
    return Series(t, u, w, speed, rate)


def read_series(path: str) -> tuple[Series, object]:
    """Read a log (:func:`companion.logs.logread.read`) and cut the fit's window from it."""
    from ..logs.logread import read
    flight = read(path)
    return series_from_flight(flight), flight


def autopilot_params(path: str, names: tuple[str, ...]) -> dict[str, float]:
    """PARAM_VALUE messages for ``names`` recorded in a .tlog (a live ``companion identify``
    reads them, so its own log carries its priors); {} for a CSV or a log without them."""
    if Path(path).suffix.lower() not in (".tlog", ".log", ".mav"):
        return {}
    from ..live.link import mavutil  # MAVLink 2 set up before pymavlink is imported
    wanted, found = set(names), {}
    try:
        conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    except Exception:  # noqa: BLE001 - read() has already said what is wrong with the file
        return {}
    try:
        while True:
            try:
                msg = conn.recv_match(type="PARAM_VALUE")
            except Exception:  # noqa: BLE001 - a torn last frame
                break
            if msg is None:
                break
            name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
            name = name.rstrip("\x00")
            if name in wanted and math.isfinite(msg.param_value):
                found[name] = float(msg.param_value)
    finally:
        conn.close()
    return found


def log_autopilot(path: str) -> AutopilotProfile | None:
    """The autopilot a .tlog was recorded with: its first vehicle HEARTBEAT's ``autopilot``
    (:func:`companion.profiles.from_heartbeat`); None for a CSV, a log without one, or an
    autopilot not driven here."""
    if Path(path).suffix.lower() not in (".tlog", ".log", ".mav"):
        return None
    from ..live.link import mavutil  # MAVLink 2 set up before pymavlink is imported
    try:
        conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    except Exception:  # noqa: BLE001 - read() has already said what is wrong with the file
        return None
    try:
        while True:
            try:
                msg = conn.recv_match(type="HEARTBEAT")
            except Exception:  # noqa: BLE001 - a torn last frame
                return None
            if msg is None:
                return None
            if conn.probably_vehicle_heartbeat(msg):
                return profiles.from_heartbeat(msg.autopilot)
    finally:
        conn.close()
