"""One log as the fit sees it (:class:`Series`: setpoints held on the measurement times and the
measured response), several logs joined into one, and PX4's velocity vectors turned into the
turn-rate commands its course loop makes of them.

Pure: arrays in, arrays out; no file, no clock.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class Series:
    """One log as the fit sees it, on the measurement times ``t`` (s, increasing): the setpoint
    in force at each sample (held since it was sent) and the measured response."""

    t: np.ndarray
    speed_cmd: np.ndarray          # m/s
    yaw_rate_cmd: np.ndarray       # rad/s
    speed: np.ndarray              # measured signed speed along the heading, m/s
    yaw_rate: np.ndarray           # measured turn rate, rad/s
    starts: tuple[int, ...] = (0,)     # first sample of each log, when several are joined
    # PX4 (velocity vectors): the course atan2(u_p) in force and the measured heading, rad;
    # ``yaw_rate_cmd`` is then derived (:func:`with_course_loop`)
    course_cmd: np.ndarray | None = None
    yaw: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.t)
        if n < 2 or any(len(a) != n for a in (self.speed_cmd, self.yaw_rate_cmd, self.speed,
                                               self.yaw_rate)):
            raise ValueError("a series needs >= 2 samples and arrays of one length")

    @property
    def segments(self) -> list[slice]:
        """Each joined log's samples (one slice for a single log)."""
        ends = self.starts[1:] + (len(self.t),)
        return [slice(a, b) for a, b in zip(self.starts, ends, strict=True)]

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def vector(self) -> bool:
        """Velocity-vector setpoints (PX4): the turn-rate command comes from the course loop."""
        return self.course_cmd is not None


def with_course_loop(series: Series, course_gain: float, min_turn_radius: float,
                     max_yaw_rate: float = math.inf) -> Series:
    """The series with the turn-rate command PX4's course loop makes of its velocity vectors
    (:meth:`companion.sim.plant.RoverModel.step_vector`), on the *measured* heading and speed:
    ``clip(K wrap(course - yaw), +-max_yaw_rate, +-|v| / R_min)``. The turn-rate channel is
    then fitted as ArduPilot's (series-parallel: the loop closed on what was measured)."""
    if series.course_cmd is None:   # (not series.vector)
        return series
    err = np.remainder(series.course_cmd - series.yaw + math.pi, 2.0 * math.pi) - math.pi
    cmd = np.clip(course_gain * err, -max_yaw_rate, max_yaw_rate)
    cmd = np.where(series.speed_cmd > 0, cmd, 0.0)          # a zero vector: no course at all
    if min_turn_radius > 0:
        top = np.abs(series.speed) / min_turn_radius
        cmd = np.clip(cmd, -top, top)
    return replace(series, yaw_rate_cmd=cmd)


def join(parts: Sequence[Series]) -> Series:
    """Several logs as one series: each next part starts one sample step after the previous
    ends, so one model is fitted to all of them (a manoeuvre and a tracking flight: the regimes
    that each determine best). Sound because every part cut by
    :func:`companion.ident.data.series_from_flight` begins at rest before its first moving
    setpoint and ends at rest after its stop: the model's state carries nothing across a seam."""
    if len(parts) == 1:
        return parts[0]
    times: list[np.ndarray] = []
    offset = 0.0
    for i, part in enumerate(parts):
        step = float(np.median(np.diff(part.t)))
        if i > 0:
            offset = times[-1][-1] + step - float(part.t[0])
        times.append(part.t + offset)
    vector = {part.vector for part in parts}
    if len(vector) > 1:
        raise ValueError("speed / turn-rate logs (ArduPilot) and velocity-vector logs (PX4) "
                         "cannot be fitted as one vehicle")
    extra = ("course_cmd", "yaw") if vector == {True} else ()
    starts = tuple(int(k) for k in np.cumsum([0] + [len(part.t) for part in parts[:-1]]))
    joined = {name: np.concatenate([getattr(part, name) for part in parts])
              for name in ("t", "speed_cmd", "yaw_rate_cmd", "speed", "yaw_rate") + extra}
    joined["t"] = np.concatenate(times)
    return Series(**joined, starts=starts)
