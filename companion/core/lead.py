"""Actuator lead: cancel a slow first-order actuator's pole (an extension beyond the paper).

The paper's plant has actuators v' = w_c (v_ref - v), omega' = w_c (omega_ref - omega) and its
Section 5 assumes them fast. A stock rover's are slow (w_c about 1.2 rad/s: 1.9 s to 90 %), and
the PZC loop, tuned for an integrator, then lags by metres or goes unstable. This stage sits
between the PZC law and the vehicle and cancels the actuator pole with a zero, pole-zero
cancellation one level down:

    a(t)  = modelled actuator output, advanced exactly over each interval with the command sent:
            a <- c + (a - c) e^{-dt / tau}                       (tau = 1 / w_c, seconds)
    c     = a + g (u - a),   g = min(1 / (1 - e^{-dt / tau}), max_gain)

where u is the law's speed or yaw-rate command. With g at its dead-beat value the modelled
actuator reaches u in one control period; ``max_gain`` bounds how hard it may kick. The result
is clamped to the limits again, and the model advances with what was actually sent, so a clamp
never makes the model drift from the vehicle. ``tau = 0`` (the default) passes commands through.

Only speed and yaw rate (what ArduPilot is sent) get the lead; the velocity vector u_p (PX4's
setpoint) is left as the law made it. Works on floats (one vehicle) or arrays (batch), no clock.
"""

from __future__ import annotations

from . import ops as _ops
from .limits import Limits, clip_yaw_rate
from .signals import Command, Num


class ActuatorLead:
    def __init__(self, tau: Num, max_gain: Num, limits: Limits = Limits(), n: int | None = None):
        self.tau, self.max_gain, self.limits, self.n = tau, max_gain, limits, n
        self._m = _ops.for_size(n)
        self._active = not _ops.is_plain_zero(tau)
        self.reset()

    def reset(self) -> None:
        zero = self._m.zeros(self.n)
        self.t: float | None = None
        self.speed_model = self.rate_model = zero       # a: the actuators start at rest
        self.speed_sent = self.rate_sent = zero         # c: what was sent last

    def step(self, t: float, cmd: Command) -> Command:
        if not self._active:
            return cmd
        m, lim = self._m, self.limits
        dt = 0.0 if self.t is None else t - self.t
        self.t = t
        tau = m.maximum(self.tau, 1e-9)
        decay = m.exp(-dt / tau)
        # Advance the actuator model over the interval that just ended.
        self.speed_model = self.speed_sent + (self.speed_model - self.speed_sent) * decay
        self.rate_model = self.rate_sent + (self.rate_model - self.rate_sent) * decay
        # The coming interval is assumed as long as the last one (dead-beat gain for it).
        gain = m.minimum(1.0 / m.maximum(1.0 - decay, 1e-12), self.max_gain) if dt > 0 else 1.0
        gain = m.where(self.tau > 0, gain, 1.0)
        speed = m.clip(self.speed_model + gain * (cmd.speed - self.speed_model),
                       -lim.max_speed, lim.max_speed)
        rate = clip_yaw_rate(m, lim, speed,
                             self.rate_model + gain * (cmd.yaw_rate - self.rate_model))
        self.speed_sent, self.rate_sent = speed, rate
        return Command(speed, rate, cmd.ux, cmd.uy)
