"""Read a flight log back: the companion's CSV, or any MAVLink .tlog (ours, MAVProxy's, QGC's).

Both come out as one :class:`Flight`: vehicle time, measured pose and speed, and whatever else
the log holds (reference, filtered pose, commands). The .tlog is read by pymavlink
(``mavutil.mavlink_connection``); a .tlog carries no reference, so one is rebuilt from the
mission (``mission=``) anchored, as the companion anchors it, at the first sample answered by a
moving setpoint (mission time 0), its mission clock replayed from the setpoints (it stands still
through failsafes and pauses).

Tracking metrics are the paper's, as :mod:`companion.live.stats` computes them live: f_cost =
sqrt(trapezoidal integral of |p_ref - p|^2 over mission time), steady RMS over the second half
of the mission time logged.

A log cut short by a crash is fine: a CSV line that does not parse is skipped and counted
(``corrupt``, with line numbers), a .tlog frame that does not parse likewise (pymavlink's
BAD_DATA).
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core import pacing
from ..errors import UserError
from ..live.config import RunnerConfig, segment_gap
from ..live.flightlog import CSV_FIELDS, STOP_FIELDS

_NUMERIC = CSV_FIELDS[:16]          # vehicle_time ... yaw_rate_cmd
# the command cells (ux, uy, speed_cmd, yaw_rate_cmd): set in an event row that sent a stop
_CMD = tuple(CSV_FIELDS.index(name) for name in STOP_FIELDS)


@dataclass
class Flight:
    source: str
    kind: str                                   # "csv" or "tlog"
    t: np.ndarray                               # vehicle time, s
    x: np.ndarray                               # measured NED position, m
    y: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray                           # measured ground speed, m/s
    yaw_rate: np.ndarray                        # measured turn rate, rad/s
    mission_t: np.ndarray | None = None         # mission time, s (with a reference)
    x_ref: np.ndarray | None = None
    y_ref: np.ndarray | None = None
    x_hat: np.ndarray | None = None             # filtered pose (CSV only)
    y_hat: np.ndarray | None = None
    yaw_hat: np.ndarray | None = None
    cmd_t: np.ndarray | None = None             # setpoints: vehicle time they answered
    speed_cmd: np.ndarray | None = None
    yaw_rate_cmd: np.ndarray | None = None
    events: list[tuple[float | None, str]] = field(default_factory=list)
    corrupt: list[int] = field(default_factory=list)   # CSV line numbers / tlog frame indices
    records: int = 0
    # Signed speed along the heading, m/s (negative when reversing): what a speed setpoint asks
    # for, so what identification compares it with (``speed`` is the unsigned ground speed).
    speed_along: np.ndarray | None = None
    # PX4's velocity-vector setpoints: the course atan2(vy, vx) each asked for (tlog only)
    course_cmd: np.ndarray | None = None

    def metrics(self) -> dict[str, Any]:
        out: dict[str, Any] = {"samples": int(len(self.t)), "records": self.records,
                               "corrupt": len(self.corrupt),
                               "vehicle_time_s": (float(self.t[-1] - self.t[0]) if len(self.t)
                                                  else 0.0)}
        if self.mission_t is None or self.x_ref is None or len(self.mission_t) < 2:
            out.update(f_cost=None, steady_rms=None, mission_time_s=None)
            return out
        mt = self.mission_t
        e2 = (self.x_ref - self.x) ** 2 + (self.y_ref - self.y) ** 2
        cost = float(np.sum(0.5 * (e2[1:] + e2[:-1]) * np.diff(mt)))
        steady = e2[mt >= 0.5 * mt[-1]]
        out.update(f_cost=math.sqrt(max(cost, 0.0)),
                   steady_rms=float(np.sqrt(np.mean(steady))) if len(steady) else None,
                   mission_time_s=float(mt[-1]), max_error=float(np.sqrt(e2.max())))
        return out


def read(path: str, mission: Any = None) -> Flight:
    """A .csv or .tlog flight log; UserError (one line, exit 2) when it cannot be read."""
    p = Path(path)
    if not p.exists():
        raise UserError(f"LOG {path}: no such file")
    if not p.is_file() or not os.access(p, os.R_OK):
        raise UserError(f"LOG {path}: not a readable file")
    suffix = p.suffix.lower()
    if suffix == ".csv":
        flight = read_csv(p)
    elif suffix in (".tlog", ".log", ".mav"):
        flight = read_tlog(p, mission)
    else:
        raise UserError(f"LOG {path}: expected a .csv or .tlog flight log")
    if len(flight.t) == 0:
        raise UserError(f"LOG {path}: no pose samples in it"
                        + (f" ({len(flight.corrupt)} corrupt records)" if flight.corrupt else ""))
    return flight


def read_csv(path: str | Path) -> Flight:
    rows: list[list[float]] = []
    modes: list[str] = []
    events: list[tuple[float | None, str]] = []
    stops: list[list[float]] = []       # setpoints sent without a sample (a failsafe's stop)
    corrupt: list[int] = []
    try:
        with open(path, newline="", encoding="utf-8", errors="replace") as f:
            reader = csv.reader(f)
            header = next(reader, None)
            if header is None or header[:len(_NUMERIC)] != _NUMERIC:
                raise UserError(f"LOG {path}: not a companion flight-log CSV (header "
                                f"{','.join((header or [])[:4])}...)")
            width = len(header)
            for line_no, row in enumerate(reader, start=2):
                if len(row) != width:
                    corrupt.append(line_no)
                    continue
                if row[-1]:
                    try:
                        vt = float(row[0]) if row[0] else None
                        stop = [float(row[i]) for i in _CMD] if row[_CMD[0]] else None
                    except ValueError:
                        corrupt.append(line_no)
                        continue
                    events.append((vt, row[-1]))
                    if vt is not None and stop is not None:
                        stops.append([vt, *stop])
                    continue
                try:
                    values = [float(v) for v in row[:len(_NUMERIC)]]
                except ValueError:
                    corrupt.append(line_no)
                    continue
                rows.append(values)
                modes.append(row[len(_NUMERIC)])
    except OSError as exc:
        raise UserError(f"LOG {path}: cannot read: {exc.strerror}") from None
    except csv.Error as exc:
        raise UserError(f"LOG {path}: not a CSV file: {exc}") from None
    a = np.array(rows, dtype=float).reshape(-1, len(_NUMERIC))
    col = {name: a[:, i] for i, name in enumerate(_NUMERIC)}
    t = col["vehicle_time"]
    speed, yaw_rate, along = _differentiate(t, col["x"], col["y"], col["yaw"])
    cmd_t, speed_cmd, yaw_rate_cmd = _commands(t, col["speed_cmd"], col["yaw_rate_cmd"], stops)
    return Flight(str(path), "csv", t, col["x"], col["y"], col["yaw"], speed, yaw_rate,
                  mission_t=col["mission_time"], x_ref=col["x_ref"], y_ref=col["y_ref"],
                  x_hat=col["x_hat"], y_hat=col["y_hat"], yaw_hat=col["yaw_hat"], cmd_t=cmd_t,
                  speed_cmd=speed_cmd, yaw_rate_cmd=yaw_rate_cmd, events=events,
                  corrupt=corrupt, records=len(rows) + len(events), speed_along=along)


def _commands(t, speed_cmd, yaw_rate_cmd, stops: list[list[float]]
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The setpoints in the order sent: each cycle's, and each event row's (a failsafe's stop,
    answering the last sample heard, so after that sample's own setpoint)."""
    if not stops:
        return t, speed_cmd, yaw_rate_cmd
    s = np.array(stops, dtype=float)
    # (the stable sort keeps a cycle's row before the event row of the same vehicle time)
    order = np.argsort(np.concatenate([t, s[:, 0]]), kind="stable")
    return (np.concatenate([t, s[:, 0]])[order],
            np.concatenate([speed_cmd, s[:, 3]])[order],
            np.concatenate([yaw_rate_cmd, s[:, 4]])[order])


def _differentiate(t, x, y, yaw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Speed, turn rate and signed speed along the heading by central differences (the CSV
    keeps poses, not velocities)."""
    if len(t) < 3:
        return np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)
    with np.errstate(divide="ignore", invalid="ignore"):
        vx, vy = np.gradient(x, t), np.gradient(y, t)
        speed = np.hypot(vx, vy)
        rate = np.gradient(np.unwrap(yaw), t)
        along = vx * np.cos(yaw) + vy * np.sin(yaw)
    return np.nan_to_num(speed), np.nan_to_num(rate), np.nan_to_num(along)


def read_tlog(path: str | Path, mission: Any = None) -> Flight:
    from ..live.link import mavutil  # MAVLink 2 set up before pymavlink is imported
    try:
        conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    except Exception as exc:  # noqa: BLE001 - pymavlink raises anything on a bad file
        # (random bytes can trip pymavlink while it sniffs the file: its message then says
        # nothing to a user, e.g. "'NoneType' object has no attribute '_instance_field'")
        raise UserError(f"LOG {path}: cannot open as a tlog: no MAVLink log in it "
                        f"({type(exc).__name__}: {exc})") from None
    vehicle: tuple[int, int] | None = None
    att: dict[tuple[int, int], tuple[float, float]] = {}
    poses: list[tuple[float, float, float, float, float, float, float]] = []
    cmds: dict[int, tuple[float, float, float]] = {}   # speed, turn rate, course
    events: list[tuple[float | None, str]] = []
    corrupt: list[int] = []
    last_t = -math.inf
    index = 0
    try:
        while True:
            try:
                msg = conn.recv_msg()
            except Exception:  # noqa: BLE001 - a torn last frame: pymavlink may raise
                corrupt.append(index)
                break
            if msg is None:
                break
            index += 1
            kind = msg.get_type()
            if kind == "BAD_DATA":
                corrupt.append(index)
                continue
            src = (msg.get_srcSystem(), msg.get_srcComponent())
            if kind == "HEARTBEAT" and vehicle is None and conn.probably_vehicle_heartbeat(msg):
                vehicle = src
            elif kind == "ATTITUDE":
                att[src] = (msg.yaw, msg.yawspeed)
            elif kind == "LOCAL_POSITION_NED" and (vehicle is None or src == vehicle):
                stamp = msg.time_boot_ms * 1e-3
                values = (msg.x, msg.y, msg.vx, msg.vy)
                if stamp <= last_t or not all(math.isfinite(v) for v in values) or src not in att:
                    continue     # a reboot, a duplicate, a bad sample: the companion refused it
                last_t = stamp
                heading, turn = att[src]
                poses.append((stamp, msg.x, msg.y, heading, math.hypot(msg.vx, msg.vy), turn,
                              msg.vx * math.cos(heading) + msg.vy * math.sin(heading)))
            elif kind == "SET_POSITION_TARGET_LOCAL_NED":
                if msg.type_mask & (1 << 11):       # yaw rate ignored: PX4's velocity vector
                    cmds[msg.time_boot_ms] = (math.hypot(msg.vx, msg.vy), math.nan,
                                              math.atan2(msg.vy, msg.vx))
                else:
                    cmds[msg.time_boot_ms] = (msg.vx, msg.yaw_rate, math.nan)
            elif kind == "STATUSTEXT" and src == vehicle:
                events.append((last_t if poses else None, f"vehicle: {msg.text}"))
    finally:
        conn.close()
    a = np.array(poses, dtype=float).reshape(-1, 7)
    t, x, y, yaw, speed, rate, along = (a[:, i] for i in range(7))
    ms = np.round(t * 1e3).astype(np.int64)
    answered = [k for k, m in enumerate(ms) if int(m) in cmds]
    flight = Flight(str(path), "tlog", t, x, y, yaw, speed, rate, events=events,
                    corrupt=corrupt, records=index, speed_along=along)
    if answered:
        flight.cmd_t = t[answered]
        flight.speed_cmd = np.array([cmds[int(ms[k])][0] for k in answered])
        flight.yaw_rate_cmd = np.array([cmds[int(ms[k])][1] for k in answered])
        course = np.array([cmds[int(ms[k])][2] for k in answered])
        if np.any(np.isfinite(course)):
            flight.course_cmd = course
    if mission is not None:
        _attach_reference(flight, mission, cmds, ms, answered)
    return flight


def _attach_reference(flight: Flight, mission: Any, cmds: dict, ms: np.ndarray,
                      answered: list[int]) -> None:
    """The reference the companion tracked, from its setpoints: its mission clock replayed.

    The tracked samples are those answered by a moving setpoint; the first anchors the
    trajectory (mission time 0). As in :class:`companion.live.loop_state.MissionClock`, mission time
    runs with vehicle time within a segment and stands still between segments: a new one begins
    after a failsafe, a pause or a re-engagement (a stop setpoint answered a sample in between:
    it rejoins the path where the rover stands and ramps up, :mod:`companion.core.pacing`)
    or a gap of more than :func:`companion.live.config.segment_gap` between tracked samples.
    A run the GNSS policy slowed (``companion.profiles.gnss``) is not replayed as slowed: its
    flight log's mission_time is the record of that.
    Samples the companion did not track are left out of the metrics, as the live ones are.
    ``answered``: the indices of the samples a setpoint answered (``ms`` in ``cmds``).
    """
    def moving(m: int) -> bool:
        return any(v != 0.0 for v in cmds[m] if math.isfinite(v))

    # the live rule: RunnerConfig's max_gap (no command sets another) and the log's own period
    period = float(np.median(np.diff(flight.t[answered]))) if len(answered) > 1 else None
    max_gap = segment_gap(RunnerConfig.max_gap, period)
    tracked: list[int] = []
    mt: list[float] = []
    stopped_since = False       # a stop setpoint answered a sample since the last tracked one
    trajectory = None
    t0 = offset = ramp_s = 0.0  # the segment's first vehicle s, its mission s, its ramp
    for k in answered:          # (the others: refused by the companion, or never read)
        if not moving(int(ms[k])):
            stopped_since = bool(tracked)
            continue
        t = float(flight.t[k])
        if trajectory is None:
            trajectory = mission.anchored(float(flight.x[k]), float(flight.y[k]),
                                          float(flight.yaw[k]))
            t0, offset, ramp_s = t, 0.0, 0.0
        elif stopped_since:
            # after standing still the live loop rejoins the path where the rover stands and
            # ramps up to speed (companion.core.pacing): the same rule
            offset, ramp_s = pacing.rejoin(trajectory, mt[-1], float(flight.x[k]),
                                           float(flight.y[k]), float(mission.duration),
                                           RunnerConfig.rejoin_accel)
            t0 = t
        elif t - float(flight.t[tracked[-1]]) > max_gap:
            t0, offset, ramp_s = t, mt[-1], 0.0   # a gap: the clock resumes where it stood
        mt.append(offset + pacing.ramp(t - t0, ramp_s)[0])
        tracked.append(k)
        stopped_since = False
    if not tracked or trajectory is None:
        return
    inside = np.array(mt) <= mission.duration + 1e-9
    keep, mission_t = np.array(tracked)[inside], np.array(mt)[inside]
    refs = [trajectory.sample(float(m)) for m in mission_t]
    for name in ("t", "x", "y", "yaw", "speed", "yaw_rate", "speed_along"):
        setattr(flight, name, getattr(flight, name)[keep])
    flight.mission_t = mission_t
    flight.x_ref = np.array([r.x for r in refs])
    flight.y_ref = np.array([r.y for r in refs])
