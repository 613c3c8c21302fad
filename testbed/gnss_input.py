"""The GNSS injector (issue 44): ArduPilot SITL's fixes from :mod:`testbed.gnss` via ``GPS_INPUT``.

SITL runs with ``GPS1_TYPE 14`` (its GPS driver takes ``GPS_INPUT`` from any link) and
``GPS1_DELAY_MS`` set to the scenario's lag (:func:`sitl_params`). :class:`GnssInjector` holds
its own link (SITL's SERIAL2, say), asks for ``SIM_STATE`` (the simulator's truth: its
``lat_int`` / ``lon_int`` extension, 1e-7 degree; the float fields are about 0.4 m coarse) at
40 Hz, and at the scenario's rate sends the truth of ``lag`` seconds ago (on the vehicle's clock,
between two SIM_STATEs: a fix exactly as old as ``GPS1_DELAY_MS`` tells the EKF) plus the
scenario's error, with its fix type and claimed accuracy. Its noise and drift run from the first fix (the
boot's); its windows (float, multipath) from each :meth:`GnssInjector.begin`, so they fall
where the scenario says into the flight that follows. Wall time is the clock: run SITL at
speedup 1.
The truth it saw is kept (``truth``: wall s, north / east metres from the first one) for
scoring, and the vehicle's clock as this link saw it (``clock``: LOCAL_POSITION_NED's
``time_boot_ms`` by wall time), which puts the truth on the vehicle's clock.
"""

from __future__ import annotations

import bisect
import math
import select
import time
from dataclasses import replace
from typing import Any

from pymavlink import mavutil

from .gnss import Fixes, Scenario, fixes
from .link_thread import LinkThread
from .scoring import EARTH, north_east

SIM_STATE = 108
LOCAL_POSITION_NED = 32
GPS_EPOCH_UNIX = 315964800             # 1980-01-06 in Unix seconds
LEAP_SECONDS = 18                      # GPS - UTC since 2017
TRUTH_HZ = 40.0                        # Rover's 50 Hz loop refuses 50 Hz (the notes)


def sitl_params(scenario: Scenario) -> dict[str, float]:
    """What SITL needs to take this scenario's fixes."""
    return {"GPS1_TYPE": 14, "GPS1_DELAY_MS": round(scenario.lag * 1000)}


def gps_time(unix: float) -> tuple[int, int]:
    """(week, ms of week) of a Unix time."""
    gps = unix - GPS_EPOCH_UNIX + LEAP_SECONDS
    week = int(gps // 604800)
    return week, int(round((gps - week * 604800) * 1000))


class GnssInjector(LinkThread):
    """A thread feeding SITL ``GPS_INPUT`` on ``url`` for a ``with`` block."""

    def __init__(self, url: str, scenario: Scenario, seed: int, duration: float = 3600.0):
        self.scenario = scenario
        self.base: Fixes = fixes(replace(scenario, windows=()), duration, seed)
        self.spoilt: Fixes = fixes(replace(scenario, white=0.0, drift=None), duration, seed + 1)
        self.k = 0                              # the next fix
        self.k_begin: int | None = None         # the fix the windows count from
        self.begin_wall: float | None = None
        self.conn = mavutil.mavlink_connection(url, source_system=255, source_component=194,
                                               dialect="ardupilotmega")
        self._walls: list[float] = []           # SIM_STATE arrivals (wall s)
        self._states: list[Any] = []
        self._vehicle_t: list[float] = []       # each SIM_STATE's vehicle time (NaN: before any)
        self.truth: list[tuple[float, float, float]] = []   # wall s, north m, east m
        # (wall s, vehicle s) of LOCAL_POSITION_NED on this same link: what puts the truth on
        # the vehicle's clock (Truth.at_vehicle), free of the other links' latency
        self.clock: list[tuple[float, float]] = []
        self.sent = 0
        self.t0: float | None = None            # wall s of the first fix
        self._origin: tuple[int, int] | None = None   # the first SIM_STATE (1e-7 degrees)
        self._prepare_thread()

    def begin(self) -> float:
        """The scenario's windows start again from the next fix; the wall time of that."""
        self.k_begin, self.begin_wall = self.k, time.time()
        return self.begin_wall

    # --- the thread -------------------------------------------------------------------------
    def _run(self) -> None:
        fd = self.conn.port.fileno()
        next_ask = 0.0
        period = 1.0 / self.scenario.rate_hz
        while not self._stop.is_set():
            now = time.time()
            if (not self._states or not self.clock) and now >= next_ask:   # until both flow
                for msg_id in (SIM_STATE, LOCAL_POSITION_NED):
                    self.conn.mav.command_long_send(1, 1, 511, 0, msg_id, 1e6 / TRUTH_HZ,
                                                    0, 0, 0, 0, 0)
                next_ask = now + 1.0
            if self._states and self.t0 is None:
                self.t0 = now
            if self.t0 is not None and now >= self.t0 + self.k * period:
                if self.k < len(self.base.t):
                    self._send(self.k, now)
                self.k += 1
            wait = (period / 4 if self.t0 is None
                    else max(0.0, self.t0 + self.k * period - now))
            try:
                ready, _, _ = select.select([fd], [], [], min(wait, 0.02))
            except (OSError, ValueError):
                return
            if ready:
                self._read()

    def _read(self) -> None:
        while (msg := self.conn.recv_msg()) is not None:
            if msg.get_type() == "LOCAL_POSITION_NED" and msg.get_srcSystem() == 1:
                if not self.clock or msg.time_boot_ms / 1000.0 > self.clock[-1][1]:
                    self.clock.append((time.time(), msg.time_boot_ms / 1000.0))
            elif msg.get_type() == "SIM_STATE":
                wall = time.time()
                self._walls.append(wall)
                self._states.append(msg)
                # its vehicle time: on from the last LOCAL_POSITION_NED of this link by the
                # wall time between their arrivals (both ride the same link's delivery)
                self._vehicle_t.append(self.clock[-1][1] + wall - self.clock[-1][0]
                                       if self.clock else math.nan)
                if self._origin is None:
                    self._origin = (msg.lat_int, msg.lon_int)
                self.truth.append((wall, *north_east(msg.lat_int, msg.lon_int,
                                                     *self._origin)))

    def _taken(self, now: float) -> tuple[float, float, float, float, Any] | None:
        """The truth ``lag`` s before the vehicle's now, as SITL will take the fix: (lat,
        lon in degrees, vn, ve m/s, the SIM_STATE nearest). On the vehicle's clock, between
        the two SIM_STATEs around it; before the clock flows, the last SIM_STATE by wall time
        (which is older by the link's delivery and up to a sample: centimetres at 1 m/s)."""
        vt, lag = self._vehicle_t, self.scenario.lag
        if self.clock and vt and math.isfinite(vt[-1]):
            when = self.clock[-1][1] + now - self.clock[-1][0] - lag
            i = bisect.bisect_right(vt, when)
            if 0 < i < len(vt) and math.isfinite(vt[i - 1]):
                s0, s1 = self._states[i - 1], self._states[i]
                a = (when - vt[i - 1]) / (vt[i] - vt[i - 1]) if vt[i] > vt[i - 1] else 0.0

                def mix(x0: float, x1: float) -> float:
                    return x0 + a * (x1 - x0)
                return (mix(s0.lat_int, s1.lat_int) * 1e-7, mix(s0.lon_int, s1.lon_int) * 1e-7,
                        mix(s0.vn, s1.vn), mix(s0.ve, s1.ve), s1 if a > 0.5 else s0)
        i = bisect.bisect_right(self._walls, now - lag) - 1
        if i < 0:
            return None
        s = self._states[i]
        return s.lat_int * 1e-7, s.lon_int * 1e-7, s.vn, s.ve, s

    def _send(self, k: int, now: float) -> None:
        """Fix ``k``: the truth of ``lag`` s ago (:meth:`_taken`) plus its error."""
        measured = now - self.scenario.lag
        taken = self._taken(now)
        if taken is None:
            return
        lat0, lon0, vn, ve, s = taken
        north, east = float(self.base.north[k]), float(self.base.east[k])
        fix_type, h_acc = int(self.base.fix_type[k]), float(self.base.h_acc[k])
        if self.k_begin is not None and 0 <= k - self.k_begin < len(self.spoilt.t):
            j = k - self.k_begin
            north, east = north + self.spoilt.north[j], east + self.spoilt.east[j]
            fix_type, h_acc = int(self.spoilt.fix_type[j]), float(self.spoilt.h_acc[j])
        lat = lat0 + math.degrees(north / EARTH)
        lon = lon0 + math.degrees(east / (EARTH * math.cos(math.radians(lat0))))
        week, week_ms = gps_time(measured)
        self.conn.mav.gps_input_send(
            int(measured * 1e6), 0, 0, week_ms, week, fix_type,
            int(round(lat * 1e7)), int(round(lon * 1e7)), s.alt, 0.8, 1.2,
            vn, ve, s.vd, 0.05, h_acc, 2 * h_acc, 20, 0)
        self.sent += 1
