"""The receiver's class as the live loop reads it, and what the profile's policy makes of it.

Pure (no I/O, no clock: every call is given its time), fed by the runner with each GPS_RAW_INT
of the vehicle. :class:`GnssWatch` keeps the class the run began with (:meth:`GnssWatch.begin`,
when the companion first engages, before the rover moves), the class now, and how long the
run's class has been back; :meth:`GnssWatch.verdict` is the policy's answer
(:func:`companion.profiles.gnss.action`: continue, slow or hold) with the words the companion
says. A receiver that has not been heard for the policy's ``stale_after`` is not judged: the
estimate's own watch (:mod:`companion.live.health`) covers a vehicle that stops reporting it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from ..profiles import gnss
from ..profiles.gnss import GnssPolicy
from .gnss_jump import JumpGuard


@dataclass
class GnssWatch:
    """The receiver's class and the run's (see the module docstring)."""

    policy: GnssPolicy
    fix: int | None = None              # GPS_RAW_INT.fix_type, last heard
    h_acc: float | None = None          # m the receiver claims (None: it claims nothing)
    heard_at: float = -math.inf         # s of the last report
    start_fix: int | None = None        # the run's class (None: not begun, or never heard)
    start_h_acc: float | None = None
    expectation: str | None = None      # what was said before the rover moved
    reports: int = 0
    _begun: bool = False
    _back_since: float | None = None    # s since the run's class is back (None: it is not)
    drops: list[dict[str, Any]] = field(default_factory=list)   # every drop: class, action, s
    jump: JumpGuard = field(default_factory=JumpGuard)          # its jumps while "fixed"

    @classmethod
    def of(cls, policy: GnssPolicy) -> GnssWatch:
        """The watch for ``policy``, its jump guard set as the policy says."""
        return cls(policy, jump=JumpGuard(threshold=policy.jump_threshold,
                                          max_ride=policy.jump_max_ride))

    def report(self, fix_type: int, h_acc_mm: int, now: float) -> str | None:
        """A GPS_RAW_INT read at ``now`` (s): a line saying the class changed, or None."""
        self.reports += 1
        old = self.fix
        self.fix, self.heard_at = int(fix_type), now
        self.h_acc = h_acc_mm / 1000.0 if h_acc_mm and h_acc_mm < 0xFFFFFFFF else None
        if self._begun and self.start_fix is None:
            self._start()                # begun before the receiver was heard: its first word
        if self.start_fix is not None:
            if gnss.rank(self.fix) >= gnss.rank(self.start_fix):
                if self._back_since is None:
                    self._back_since = now
            else:
                self._back_since = None
        if old is None or gnss.rank(old) == gnss.rank(self.fix):
            return None
        return f"GNSS {gnss.name(old)} -> {gnss.name(self.fix)}{self._claim()}"

    def begin(self) -> str:
        """The run begins (the companion engaged): its class is the receiver's now. What to
        expect, to say before the rover moves."""
        self._begun = True
        if self.fix is None:
            return ("GNSS quality unknown (no GPS_RAW_INT heard yet): its class is judged from "
                    "its first report")
        return self._start()

    def _start(self) -> str:
        assert self.fix is not None
        self.start_fix, self.start_h_acc = self.fix, self.h_acc
        self.expectation = gnss.expectation(self.fix, self.h_acc)
        return self.expectation

    @property
    def begun(self) -> bool:
        return self._begun

    def short(self) -> str:
        """The receiver now, in a few words (a STATUSTEXT's)."""
        if self.fix is None:
            return "quality unknown"
        return gnss.name(self.fix) + (f" +-{self.h_acc:.2f} m" if self.h_acc is not None else "")

    def fresh(self, now: float) -> bool:
        return now - self.heard_at <= self.policy.stale_after

    def verdict(self, now: float) -> tuple[str, str]:
        """(action, why): the policy's answer for the receiver now."""
        if self.start_fix is None or self.fix is None or not self.fresh(now):
            return gnss.CONTINUE, ""
        act = gnss.action(self.policy, self.start_fix, self.fix)
        if act == gnss.CONTINUE:
            return act, ""
        why = (f"GNSS {gnss.name(self.fix)}{self._claim()}, below the run's "
               f"{gnss.name(self.start_fix)}")
        return act, why

    def noted(self, act: str, now: float) -> None:
        """A drop acted on (for the run's JSON)."""
        assert self.fix is not None
        self.drops.append({"fix": gnss.name(self.fix), "h_acc": self.h_acc, "action": act,
                           "at": now})

    def back(self, now: float) -> bool:
        """The run's class back for the policy's ``back_for`` s (or the receiver unheard)."""
        if not self.fresh(now) or self.start_fix is None:
            return True
        return self._back_since is not None and now - self._back_since >= self.policy.back_for

    def _claim(self) -> str:
        return f" (claims {self.h_acc:.2f} m)" if self.h_acc is not None else ""

    def status(self) -> dict[str, Any]:
        """The Zenoh status's and the JSON's ``gnss``."""
        return {"fix": gnss.name(self.fix) if self.fix is not None else None,
                "fix_type": self.fix, "h_acc": self.h_acc,
                "run_fix": gnss.name(self.start_fix) if self.start_fix is not None else None,
                "run_h_acc": self.start_h_acc, "expectation": self.expectation,
                "drops": len(self.drops)}

    def summary(self) -> dict[str, Any]:
        return {**self.status(), "reports": self.reports, "drop_log": list(self.drops),
                "jumps_ridden": self.jump.jumps}
