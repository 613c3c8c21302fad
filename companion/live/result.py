"""What a flight returns: the :class:`RunResult` ``companion run --json`` and ``companion demo
--json`` print, and :func:`result_of`, which builds it from the loop's stats at the end of a
session (:func:`companion.live.session.fly`)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

from . import policy
from .runner.core import stop_cause


@dataclass
class RunResult:
    """The result object ``companion run --json`` and ``companion demo --json`` print."""

    reason: str                      # mission_done, signal, aborted, failsafe: ..., ...
    exit_code: int
    f_cost: float
    steady_rms: float
    setpoints_sent: int
    telemetry_received: int          # LOCAL_POSITION_NED from the vehicle, refused ones included
    telemetry_rejected: dict[str, int]
    cycles: int                      # tracking cycles (one setpoint each)
    loop_rate_hz: float              # tracking cycles per vehicle second
    latency_p50_ms: float
    latency_p99_ms: float
    latency_max_ms: float
    missed_cycles: int               # gaps + overruns
    overruns: int
    duration_s: float                # mission time tracked
    wall_s: float                    # companion wall time from connect to exit
    rate_requested_hz: float
    rate_accepted_hz: float | None
    autopilot: str
    sysid: int
    gains: dict[str, Any]
    gains_source: str
    limits: dict[str, float | None]   # None: no limit (JSON null)
    failsafes: int
    hold_confirmed: bool
    mission: str
    extra: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.update(d.pop("extra"))
        # JSON has no NaN/inf: say null instead.
        for key, value in d.items():
            if isinstance(value, float) and not math.isfinite(value):
                d[key] = None
        return d


def result_of(outcome: Any, runner: Any, link: Any, vehicle: Any, flown: Any, rate: float,
              accepted: float | None, wall_s: float, extra: dict[str, Any]) -> RunResult:
    """The session's result: the loop's ``outcome`` and stats (``runner``), the ``link``'s
    counters, the ``vehicle`` found, what was ``flown`` (a session's resolved flight: gains,
    their source, limits, the tracker's name), the rates asked and accepted; ``extra``: what
    the session adds to the loop's own figures."""
    st, t = runner.stats, runner.telemetry
    lat = st.latency
    return RunResult(
        reason=outcome.reason, exit_code=outcome.exit_code,
        f_cost=st.f_cost, steady_rms=st.steady_rms,
        setpoints_sent=link.setpoints_sent, telemetry_received=t.received,
        telemetry_rejected=dict(t.rejected), cycles=st.cycles, loop_rate_hz=st.loop_rate_hz,
        latency_p50_ms=lat.percentile(50) * 1e3, latency_p99_ms=lat.percentile(99) * 1e3,
        latency_max_ms=lat.max_s * 1e3 if lat.n else math.nan,
        missed_cycles=st.gaps + st.overruns, overruns=st.overruns,
        duration_s=runner.mission_time, wall_s=wall_s,
        rate_requested_hz=rate, rate_accepted_hz=accepted,
        autopilot=vehicle.autopilot, sysid=vehicle.sysid,
        gains=flown.gains, gains_source=flown.gains_source,
        limits=policy.limits_dict(flown.limits),
        failsafes=outcome.failsafes, hold_confirmed=outcome.hold_confirmed,
        mission=runner.mission.name,
        extra={"controller": flown.tracker.name, "stop_cause": stop_cause(outcome.exit_code),
               **extra, "missed_gaps": st.gaps, "backlog": st.backlog,
               "sink_errors": runner.sink_errors, "signing_rejected": link.signing_rejected,
               "tracker_resets": runner.tracker_resets, "stalls": runner.stalls,
               "udp_recv_buffer": link.recv_buffer, "tcp_reconnects": link.reconnects})
