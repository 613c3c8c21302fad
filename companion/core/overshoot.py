"""Overshoot cancellation: undo a speed loop's overshoot before the command leaves (an extension
beyond the paper, pole-zero cancellation one level down, like :mod:`companion.core.lead`).

Some speed loops answer a change of their target with more than the change and take the excess
back later: ArduPilot's PI speed loop behind a throttle feed-forward that over-drives (SITL's
Ackermann ``rover``: 1.4 x the command's swing at the 0.08 Hz ellipse's 1 rad/s). The vehicle
model (:mod:`companion.sim.plant`) has it as a lead-lag on the channel's output x,

    v = (1 + g) x - g z,   z' = (x - z) / tau          i.e.  (1 + (1 + g) tau s) / (1 + tau s)

with g the overshoot share and tau the time it is taken back over (the vehicle file's
``speed.overshoot`` and ``speed.overshoot_s``). This stage sends its exact inverse, a lag-lead
(1 + tau s) / (1 + (1 + g) tau s): for the law's speed u it sends

    c = (u + g w) / (1 + g),   w <- c + (w - c) e^{-dt / tau}   (w: the vehicle's z, modelled)

so that c + g (c - w) = u: the overshoot the vehicle adds, the command has taken out. The
cancelled pole, -1 / ((1 + g) tau), is stable, and c is a convex blend of u and w, so it stays
within the speed limit; the turn rate is clipped to what the sent speed allows (a car's
turning radius). ``g = 0`` (the default) passes everything through. Floats (one vehicle) or
arrays (batch), no clock.
"""

from __future__ import annotations

from . import ops as _ops
from .limits import Limits, clip_yaw_rate
from .signals import Command, Num


class OvershootCancel:
    def __init__(self, share: Num, tau: Num, limits: Limits = Limits(), n: int | None = None):
        self.share, self.tau, self.limits, self.n = share, tau, limits, n
        self._m = _ops.for_size(n)
        self.active = not _ops.is_plain_zero(share)
        self.reset()

    def reset(self) -> None:
        self.t: float | None = None
        self.slow: Num = self._m.zeros(self.n)     # w: the overshoot's slow state, modelled
        self.sent: Num = self._m.zeros(self.n)     # c: the speed sent last

    def step(self, t: float, cmd: Command) -> Command:
        if not self.active:
            return cmd
        m, g = self._m, self.share
        if self.t is not None:           # the first command meets a vehicle at rest (w = 0)
            decay = m.exp(-(t - self.t) / m.maximum(self.tau, 1e-9))
            self.slow = self.sent + (self.slow - self.sent) * decay
        self.t = t
        speed = (cmd.speed + g * self.slow) / (1.0 + g)
        self.sent = speed
        return Command(speed, clip_yaw_rate(m, self.limits, speed, cmd.yaw_rate), cmd.ux, cmd.uy)
