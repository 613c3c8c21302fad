"""The vehicle's health as the live loop reads it: its position estimate and its own failsafes.

Two watchers, pure (no I/O, no clock: every call is given its time), fed by the runner
(:mod:`companion.live.runner`) from the messages it reads:

* :class:`EstimateWatch`: is the position estimate fit to steer by? Unfit while the estimator's
  report (EKF_STATUS_REPORT on ArduPilot, ESTIMATOR_STATUS on PX4: the profile's
  :class:`~companion.profiles.autopilot.EstimateFacts`) lacks a needed bit (absolute or relative
  horizontal position), shows a bad one (constant-position mode, GPS glitching) or a test ratio
  over ``variance_limit``; and after a LOCAL_POSITION_NED step that the reported velocity does
  not explain (an EKF reset, a lane switch, a fall-back to DCM) by more than ``step_limit``.
  Fit again once nothing of that has been seen for ``healthy_for`` seconds.
* :class:`FailsafeWatch`: is the autopilot's own failsafe holding the vehicle, and which? From
  its STATUSTEXTs (the profile's :class:`~companion.profiles.autopilot.FailsafeFacts` texts)
  and the HEARTBEAT's ``system_status``. :meth:`FailsafeWatch.who_left` says who took the
  vehicle out of the track mode: the autopilot's failsafe (named), the autopilot's answer to
  the companion's own silence, the companion's own HOLD, or a pilot / ground station.

What each ending means for the exit code is :class:`companion.errors.ExitCode`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..profiles.autopilot import EstimateFacts, FailsafeFacts
from .gnss_watch import GnssWatch

# Who took the vehicle out of the track mode (FailsafeWatch.who_left).
AUTOPILOT = "autopilot"     # the autopilot's own failsafe: never taken back on our own
LINK = "link"               # its answer to the companion's silence: taken back once the link is
OURS = "ours"               # the companion's own HOLD, arriving now
PILOT = "pilot"             # a pilot or a ground station

TEXT_MEMORY = 10.0          # s: a failsafe STATUSTEXT names the cause of a mode change this long


@dataclass
class EstimateWatch:
    """Whether the position estimate may steer the rover (see the module docstring)."""

    facts: EstimateFacts
    variance_limit: float = 0.8       # the estimator's test ratios (1 = its own gate)
    step_limit: float = 1.0           # m of position change the velocity does not explain
    healthy_for: float = 3.0          # s of health before the estimate is trusted again
    max_step_dt: float = 0.5          # s: longer between samples is a gap, not a step
    reports: int = 0                  # estimator reports read
    _flag_problem: str | None = None  # what the last report says is wrong
    _step_problem: str | None = None  # the last unexplained step, until healthy_for passes
    _bad_until: float = -math.inf     # s: unhealthy at least until then
    _last: tuple[float, float, float, float, float] | None = None   # t, x, y, vx, vy
    _shown: int = 0                   # every flag any report has set (facts.once_shown)
    gnss: GnssWatch | None = None     # the receiver behind the estimate (gnss_watch)

    def report(self, flags: int, ratios: dict[str, float], now: float) -> None:
        """An estimator report (its flags and test ratios) read at ``now`` (s)."""
        self.reports += 1
        self._shown |= flags
        waived = self.facts.once_shown & ~self._shown     # never had it: not lost either
        problems = [what for bit, what in self.facts.need if not flags & bit and not bit & waived]
        problems += [what for bit, what in self.facts.bad if flags & bit]
        for name in self.facts.variances:
            value = ratios.get(name)
            if value is not None and not (math.isfinite(value) and value <= self.variance_limit):
                problems.append(f"{name} {value:.2f} over {self.variance_limit:g}")
        was_bad = self._flag_problem is not None
        self._flag_problem = (f"{self.facts.message} flags 0x{flags:x}: " + ", ".join(problems)
                              if problems else None)
        if problems or was_bad:
            # healthy_for counts from the first healthy report
            self._bad_until = now + self.healthy_for

    def position(self, t: float, x: float, y: float, vx: float, vy: float,
                 now: float) -> str | None:
        """One accepted LOCAL_POSITION_NED (vehicle time ``t``): the step it makes that its
        velocity does not explain, or None. The velocity is averaged over the interval (the
        trapezoid rule), so steady driving and braking leave no residual."""
        last, self._last = self._last, (t, x, y, vx, vy)
        if last is None:
            return None
        t0, x0, y0, vx0, vy0 = last
        dt = t - t0
        if not 0.0 < dt <= self.max_step_dt:
            return None
        ex = x - (x0 + 0.5 * (vx + vx0) * dt)
        ey = y - (y0 + 0.5 * (vy + vy0) * dt)
        residual = math.hypot(ex, ey)
        if residual <= self.step_limit:
            return None
        moved = math.hypot(x - x0, y - y0)
        self._step_problem = (f"LOCAL_POSITION_NED stepped {moved:.2f} m in {dt * 1e3:.0f} ms, "
                              f"{residual:.2f} m more than its velocity explains")
        self._bad_until = now + self.healthy_for
        return self._step_problem

    def problem(self, now: float) -> str | None:
        """What is wrong with the estimate now (None: nothing seen lately)."""
        if self._flag_problem is not None:
            return self._flag_problem
        if now < self._bad_until and self._step_problem is not None:
            return self._step_problem
        return None

    def healthy(self, now: float) -> bool:
        """Healthy, and for ``healthy_for`` s already."""
        return self._flag_problem is None and now >= self._bad_until

    def forget_position(self) -> None:
        """The next position starts afresh (after a gap the watch did not see)."""
        self._last = None


@dataclass
class FailsafeWatch:
    """The autopilot's own failsafes, from its STATUSTEXTs and heartbeats."""

    facts: FailsafeFacts
    critical: bool = False                        # the last heartbeat's system_status says so
    last: tuple[str, str, float] | None = None    # (cause, text, s) of the last failsafe text
    cleared_at: float = -math.inf                 # s of the last "cleared" text
    seen: list[tuple[str, str]] = field(default_factory=list)   # every (cause, text), in order
    sensor_health: int | None = None              # the last SYS_STATUS health bits

    def text(self, text: str, now: float) -> str | None:
        """A STATUSTEXT of the vehicle: the failsafe cause it names, or None."""
        low = text.lower()
        if any(piece in low for piece in self.facts.cleared):
            self.cleared_at = now
            return None
        for piece, cause in self.facts.texts:
            if piece in low:
                self.last = (cause, text, now)
                self.seen.append((cause, text))
                return cause
        return None

    def sys_status(self, enabled: int, health: int, now: float) -> str | None:
        """A SYS_STATUS of the vehicle: the cause whose sensor bit (one the autopilot reports
        enabled) has just turned unhealthy, as :meth:`text` would name it; None otherwise. The
        bit turning healthy again clears that cause, as a "cleared" text would."""
        # a bit not enabled counts as healthy: enabling it unhealthy is news too
        before, self.sensor_health = self.sensor_health, health | (~enabled & 0xFFFFFFFF)
        named = None
        for bit, cause in self.facts.sensors:
            if not enabled & bit:
                continue
            if not health & bit and (before is None or before & bit):
                said = f"SYS_STATUS: {cause} unhealthy"
                self.seen.append((cause, said))
                named = named or cause
                live = self._live_text(now)
                if live is None or live[0] != cause:
                    self.last = (cause, said, now)   # (the autopilot's own words, if any, stay)
            elif (health & bit and before is not None and not before & bit
                  and self.last is not None and self.last[0] == cause):
                self.cleared_at = now
        return named

    def heartbeat(self, system_status: int) -> None:
        self.critical = system_status in self.facts.states

    def setpoints_lost(self, cause: str | None) -> bool:
        """A text of ``cause`` (:meth:`text`'s answer) says the companion's setpoints stopped
        reaching the vehicle while it stays in the track mode (ArduPilot's guided timeout:
        "target not received last 3secs, stopping"): the link is silent towards the vehicle
        though telemetry still flows. An autopilot that leaves the track mode on that silence
        (PX4's offboard loss) says so by its mode instead (:meth:`who_left`)."""
        return (cause is not None and cause in self.facts.link_causes
                and not self.facts.leaves_on_silence)

    def active(self, now: float) -> tuple[str, str] | None:
        """(cause, what says so) of the autopilot's failsafe holding the vehicle, or None.
        A failsafe text counts for :data:`TEXT_MEMORY` s unless a "cleared" text followed it;
        a critical system_status counts for as long as it lasts."""
        live = self._live_text(now)
        if live is not None:
            return live[0], f'"{live[1]}"'
        last = self.last
        if self.critical:
            if last is not None and self.cleared_at < last[2]:
                return last[0], f'"{last[1]}" and system_status critical'
            return "failsafe", "system_status critical"
        return None

    def _live_text(self, now: float) -> tuple[str, str, float] | None:
        """The last failsafe text (or sensor news) if it still counts: within
        :data:`TEXT_MEMORY` s and no "cleared" since."""
        last = self.last
        if last is not None and now - last[2] <= TEXT_MEMORY and self.cleared_at < last[2]:
            return last
        return None

    def who_disarmed(self, now: float) -> tuple[str, str]:
        """Who disarmed the vehicle while it stayed in the track mode, and why (for the log)."""
        active = self.active(now)
        if active is not None and active[0] not in self.facts.link_causes:
            return AUTOPILOT, (f"the autopilot's {active[0]} failsafe ({active[1]}) disarmed the "
                               "vehicle")
        return PILOT, "vehicle disarmed by someone else"

    def cleared(self, now: float) -> bool:
        """No failsafe holds the vehicle any more (status not critical, no live text)."""
        return self.active(now) is None

    def who_left(self, mode: str, hold_mode: str, now: float, companion_stalled: bool,
                 hold_asked: bool) -> tuple[str, str]:
        """Who took the vehicle out of the track mode into ``mode``, and why (for the log).

        ``companion_stalled``: the companion is in its own failsafe for silence (no telemetry,
        no heartbeat), so its setpoints may not be arriving either; ``hold_asked``: it asked
        for ``hold_mode`` itself and has not seen it yet."""
        active = self.active(now)
        silence = mode == hold_mode and companion_stalled
        link = self.facts.link_causes
        if silence and self.facts.leaves_on_silence and (
                active is None or active[0] in link or active[1] == "system_status critical"):
            # PX4 leaves OFFBOARD when the setpoints stop: while the companion's link is
            # silent that is the expected answer (its status turns critical with it).
            why = f" ({active[1]})" if active is not None else ""
            return LINK, (f"the autopilot switched to {mode}{why} while the companion's link "
                          "was silent (its setpoint-loss failsafe)")
        if active is not None and active[0] not in link:
            cause, why = active
            name = "own" if cause == "failsafe" else cause
            return AUTOPILOT, f"the autopilot's {name} failsafe ({why}) switched to {mode}"
        if mode == hold_mode and hold_asked:
            return OURS, f"the companion's own {hold_mode} request arrived"
        # A guided-timeout text does not make a later mode change the autopilot's: that
        # timeout stops the rover inside the track mode.
        return PILOT, f"mode changed to {mode} by someone else"
