"""One companion session: settings in, RunResult out (what ``companion run`` and ``demo`` share).

Connect, wait for the vehicle, negotiate the telemetry rate, pick gains and limits for the rate
the vehicle actually accepted, build the tracker, run the loop (:mod:`companion.live.runner`).

Where each setting comes from, first found wins:

* rate: ``--rate``; the mission's ``rate_hz``; the ``--gains`` file's ``rate_hz``; 40 Hz.
* gains (filter and PZC parts separately): ``--k-df/--lambda-f/--k-dc/--lambda-c`` field by
  field over ``--gains FILE``; the mission's gains; the shipped tuned gains for the accepted
  rate, the vehicle's w_c and d_cen (:func:`companion.sim.gains.find_tuned`); the paper's gains.
* limits: ``--max-speed/--max-yaw-rate``; the mission's [limits]; :data:`DEFAULT_LIMITS`.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Callable, Sequence

from ..sim import gains as gains_mod
from ..errors import UserError
from .events import ControlChannel, Sink
from ..core.filter import FilterGains
from ..core.limits import Limits
from ..core.pzc import PZCGains
from . import origin as origin_mod
from .runner import Runner, RunnerConfig
from .stats import RunResult

DEFAULT_RATE = 40.0
MAX_RATE = 1000.0
# A ceiling for a vehicle whose limits nobody gave: above what the paper's ellipse needs at
# 0.12 Hz (peak 4.8 m/s), and a turn rate the 40 Hz yaw loop can use without chattering.
DEFAULT_LIMITS = Limits(max_speed=6.0, max_yaw_rate=6.0)
PAPER_W_C = 20.0


@dataclass(frozen=True)
class GainFlags:
    k_df: float | None = None
    lambda_f: float | None = None
    k_dc: float | None = None
    lambda_c: float | None = None


@dataclass(frozen=True)
class RunSettings:
    link: Any                          # companion.live.link.LinkConfig
    mission: Any                       # companion.mission.Mission
    runner: RunnerConfig = RunnerConfig()
    rate: float | None = None          # --rate
    gains_file: str | None = None      # --gains
    gain_flags: GainFlags = GainFlags()
    max_speed: float | None = None
    max_yaw_rate: float | None = None
    w_c: float | None = None           # the vehicle's, to pick shipped tuned gains
    d_cen: float | None = None
    realtime: bool = False             # --realtime: SCHED_FIFO for the loop
    vehicle_gains: Any = None          # TunedGains for --vehicle / the mission's [vehicle] file
    vehicle_limits: Limits | None = None   # that vehicle's top speed and turn rate
    origin: tuple[float, float] | None = None   # --origin: checked against the vehicle's
    origin_timeout: float = 60.0       # wall s to wait for the vehicle's EKF origin


REALTIME_PRIORITY = 10   # low among real-time tasks: above every normal process, below the kernel's


def take_realtime(log: Callable[[str], None]) -> bool:
    """SCHED_FIFO for this process, so a busy board does not delay a kHz loop. Best effort:
    without the privilege the loop runs at normal priority and says so."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
    except (AttributeError, OSError) as exc:
        log(f"--realtime: SCHED_FIFO not granted ({exc}); running at normal priority")
        return False
    log(f"--realtime: control loop under SCHED_FIFO priority {REALTIME_PRIORITY}")
    return True


@dataclass
class Choice:
    filter: FilterGains
    pzc: PZCGains
    source: str
    tuned_rate: float | None = None
    notes: list[str] = field(default_factory=list)


class StopSwitch:
    """What a signal handler calls: before the loop runs it interrupts the set-up, once the
    loop runs it asks the loop to stop the rover and finish."""

    def __init__(self) -> None:
        self.runner: Runner | None = None
        self.reason: str | None = None

    def trigger(self, reason: str) -> None:
        self.reason = reason
        if self.runner is None:
            raise KeyboardInterrupt(reason)
        self.runner.request_stop(reason)


def requested_rate(s: RunSettings) -> float:
    rate = s.rate or s.mission.rate_hz
    if rate is None and s.gains_file is not None:
        file_rate = gains_mod.load(s.gains_file).rate_hz
        rate = file_rate if math.isfinite(file_rate) else None
    rate = rate or DEFAULT_RATE
    if not (math.isfinite(rate) and 0 < rate <= MAX_RATE):
        raise UserError(f"rate must be between 0 and {MAX_RATE:g} Hz, not {rate!r}")
    return rate


def vehicle_keys(s: RunSettings) -> tuple[float, float]:
    v = s.mission.vehicle
    w_c = s.w_c if s.w_c is not None else (v.w_c if v is not None else PAPER_W_C)
    d_cen = s.d_cen if s.d_cen is not None else (v.d_cen if v is not None else 0.0)
    return float(w_c), float(d_cen)


def choose_gains(s: RunSettings, rate: float) -> Choice:
    m = s.mission
    file = gains_mod.load(s.gains_file) if s.gains_file else None
    w_c, d_cen = vehicle_keys(s)
    shipped = gains_mod.find_tuned(rate, w_c, d_cen) or gains_mod.find_tuned(rate, w_c)
    own = s.vehicle_gains
    filt, fsrc = ((file.filter, f"--gains {s.gains_file}") if file else
                  (m.filter_gains, f"mission {m.source}") if m.filter_gains else
                  (own.filter, f"vehicle {own.source}") if own else
                  (shipped.filter, f"shipped {shipped.source}") if shipped else
                  (FilterGains(), "paper"))
    pzc, psrc = ((file.pzc, f"--gains {s.gains_file}") if file else
                 (m.pzc_gains, f"mission {m.source}") if m.pzc_gains else
                 (own.pzc, f"vehicle {own.source}") if own else
                 (shipped.pzc, f"shipped {shipped.source}") if shipped else
                 (PZCGains(), "paper"))
    f = s.gain_flags
    if f.k_df is not None or f.lambda_f is not None:
        filt = replace(filt, **{k: v for k, v in (("k_df", f.k_df), ("lambda_f", f.lambda_f))
                                if v is not None})
        fsrc = f"flags over {fsrc}"
    if f.k_dc is not None or f.lambda_c is not None:
        pzc = replace(pzc, **{k: v for k, v in (("k_dc", f.k_dc), ("lambda_c", f.lambda_c))
                              if v is not None})
        psrc = f"flags over {psrc}"
    source = fsrc if fsrc == psrc else f"filter: {fsrc}; pzc: {psrc}"
    tuned_rate = own.rate_hz if own else (shipped.rate_hz if shipped else None)
    return Choice(filt, pzc, source, tuned_rate)


def choose_limits(s: RunSettings) -> Limits:
    base = s.mission.limits or s.vehicle_limits or DEFAULT_LIMITS
    try:
        return Limits(max_speed=s.max_speed if s.max_speed is not None else base.max_speed,
                      max_yaw_rate=(s.max_yaw_rate if s.max_yaw_rate is not None
                                    else base.max_yaw_rate))
    except ValueError as exc:
        raise UserError(str(exc)) from None


def gains_dict(filt: FilterGains, pzc: PZCGains) -> dict[str, Any]:
    d = {"k_df": float(filt.k_df), "lambda_f": float(filt.lambda_f)}
    for key, value in asdict(pzc).items():
        d[key] = value if value is None or isinstance(value, (bool, str)) else float(value)
    return d


def _finite_or_none(x: float) -> float | None:
    return x if math.isfinite(x) else None


def fly(s: RunSettings, sinks: Sequence[Sink] = (), control: ControlChannel | None = None,
        log: Callable[[str], None] = lambda text: None,
        switch: StopSwitch | None = None,
        make_tracker: Callable[[Any, Limits], Any] | None = None) -> RunResult:
    """Run one session against a live vehicle; raises UserError for a user's problem.

    ``make_tracker(link, limits)``, if given, builds the tracker instead of the PZC tracker
    (``companion identify`` flies its excitation manoeuvre so); it runs once the vehicle is
    known and its telemetry rate agreed, and may read from the link (parameters) meanwhile.
    """
    from .link import HOLD_MODE, TRACK_MODE, Link
    from ..core.pzc import PZCTracker

    wall0 = time.perf_counter()
    if s.gains_file is not None:
        gains_mod.load(s.gains_file)     # a bad file is a user error before anything connects
    rate = requested_rate(s)
    limits = choose_limits(s)
    link = Link(s.link)
    try:
        stop = (lambda: False) if switch is None else (lambda: switch.reason is not None)
        vehicle = link.wait_vehicle(stop)
        log(f"{vehicle.autopilot} vehicle, system {vehicle.sysid} component {vehicle.compid}, "
            f"mode {link.mode}, {'armed' if link.armed else 'disarmed'}")
        for name in (TRACK_MODE[vehicle.autopilot], HOLD_MODE[vehicle.autopilot]):
            if name not in (link.master.mode_mapping() or {}):
                raise UserError(f"the vehicle reports no {name} mode (MAV_TYPE {vehicle.mav_type})")
        mission, origin = s.mission, None
        if mission.geodetic:
            # Placed by latitude / longitude: around the vehicle's own EKF origin, which its
            # LOCAL_POSITION_NED is relative to (not the plan's home, nor a guess).
            mission, origin = origin_mod.place(mission, link, s.origin, s.origin_timeout, log,
                                               stop)
        accepted, notes = link.negotiate_rate(rate)
        for note in notes:
            log(note)
        log(f"telemetry at {accepted:g} Hz" if accepted else "telemetry rate not confirmed")
        choice = choose_gains(s, accepted or rate)
        log(f"gains: {choice.source}; limits: speed {limits.max_speed:g} m/s, "
            f"yaw rate {limits.max_yaw_rate:g} rad/s")
        tracker = (PZCTracker(choice.filter, choice.pzc, limits) if make_tracker is None
                   else make_tracker(link, limits))
        config = replace(s.runner, period=1.0 / accepted if accepted else None)
        runner = Runner(link, tracker, mission, config, limits, sinks, control, log,
                        origin=origin.latlon if origin is not None else None)
        # Sinks that write files (the flight-log CSV) flush when the loop is about to sleep.
        link.on_idle.extend(idle for sink in sinks if (idle := getattr(sink, "idle", None)))
        if switch is not None:
            switch.runner = runner
            if switch.reason is not None:
                runner.request_stop(switch.reason)
        if s.realtime:
            take_realtime(log)
        outcome = runner.run()
    finally:
        link.close()
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
        duration_s=runner.mission_time, wall_s=time.perf_counter() - wall0,
        rate_requested_hz=rate, rate_accepted_hz=accepted,
        autopilot=vehicle.autopilot, sysid=vehicle.sysid,
        gains=gains_dict(choice.filter, choice.pzc), gains_source=choice.source,
        limits={"max_speed": _finite_or_none(limits.max_speed),
                "max_yaw_rate": _finite_or_none(limits.max_yaw_rate)},
        failsafes=outcome.failsafes, hold_confirmed=outcome.hold_confirmed,
        mission=runner.mission.name,
        extra={**({"ekf_origin": origin.as_dict()} if origin is not None else {}),
               "missed_gaps": st.gaps, "backlog": st.backlog,
               "sink_errors": runner.sink_errors, "signing_rejected": link.signing_rejected,
               "tracker_resets": runner.tracker_resets, "udp_recv_buffer": link.recv_buffer})
