"""Course over ground: steer the direction the rover moves, not the heading it reports.

An extension beyond the paper. The paper's rover moves along its heading (a unicycle,
p' = v [cos phi, sin phi]), so eqs. (20) and (22) turn the heading phi-hat onto the course of
u_p. A real rover's velocity is off its reported heading by a slowly varying angle beta:

    p' = v [cos(phi + beta), sin(phi + beta)]

from a compass or EKF yaw error, a GPS antenna or IMU ahead of the turning centre, tyres that
slip in a turn. The yaw loop then holds phi on the course of u_p and the rover drifts sideways at
v sin(beta) until the position loop's error pushes back: a steady offset of about
v beta / K_P to one side of the path. Its integrator cannot remove it, because the offset turns
with the path (in the world frame it is a sinusoid at the reference's frequency). ArduPilot SITL
shows it: about 0.03 rad inward on the paper's ellipse at 0.08 Hz (3 m/s), 6-9 cm inside the
path on both its skid-steer and its Ackermann rover.

The estimate is model-free, from the filtered pose of successive steps (the filter's rate
states are not velocities: it holds each sample, :mod:`companion.core.filter`). Each step's
displacement d = p_hat(t) - p_hat(t - dt) is split along and across the heading half-way
through the step, phi_mid, and both parts are summed with exponential forgetting:

    A <- e^{-dt / tau} A + d . [cos phi_mid, sin phi_mid]
    L <- e^{-dt / tau} L + d . [-sin phi_mid, cos phi_mid]
    beta = clip(atan2(L, A), +-max_angle)

Summing displacements before taking the angle matters: the position noise of successive
differences cancels in the sum (it telescopes), so beta's noise is the position noise over the
distance of about one tau, not one step's angle noise averaged (at 40 Hz and 1.6 m/s, 5 mm of
noise makes each step's angle uncertain by 0.18 rad). The sums advance only while the rover
moves forward faster than ``min_speed`` (at a standstill the course means nothing; reversing is
left to the heading); otherwise beta is held. The law then steers ``phi_hat + beta``
(:meth:`CourseCorrection.step` returns the estimate with that yaw).
``tau`` 0 switches it off: the paper's law exactly. Floats (one vehicle) or arrays (batch).
"""

from __future__ import annotations

from . import ops as _ops
from .signals import Estimate, Num

MIN_SPEED = 0.5     # m/s forward: below it the course is too noisy to learn from
MAX_ANGLE = 0.35    # rad (20 deg): the most the heading is trusted to be off its course


class CourseCorrection:
    """beta-hat, the low-passed angle from the reported heading to the course over ground."""

    def __init__(self, tau: Num, n: int | None = None, min_speed: float = MIN_SPEED,
                 max_angle: float = MAX_ANGLE):
        self.tau, self.n, self.min_speed, self.max_angle = tau, n, min_speed, max_angle
        self._m = _ops.for_size(n)
        self.active = not _ops.is_plain_zero(tau)
        self.reset()

    def reset(self) -> None:
        zero = self._m.zeros(self.n)
        self.t: float | None = None
        self.beta: Num = zero
        self.along: Num = zero         # A: forgetful sum of the displacement along the heading, m
        self.across: Num = zero        # L: ... and across it (positive towards +yaw), m
        self._last: Estimate | None = None

    def step(self, t: float, est: Estimate) -> Estimate:
        """Learn from the filtered pose at ``t`` and return it with the course as its yaw."""
        if not self.active:
            return est
        m, last = self._m, self._last
        self._last = est
        dt = 0.0 if self.t is None else t - self.t
        self.t = t
        if last is not None and dt > 0.0:
            dx, dy = est.x - last.x, est.y - last.y
            heading = last.yaw + 0.5 * m.wrap(est.yaw - last.yaw)
            c, s = m.cos(heading), m.sin(heading)
            along, across = dx * c + dy * s, dy * c - dx * s
            learn = (along > self.min_speed * dt) & (self.tau > 0)    # bools or bool arrays
            keep = m.where(learn, m.exp(-dt / m.maximum(self.tau, 1e-9)), 1.0)
            self.along = keep * self.along + m.where(learn, along, 0.0)
            self.across = keep * self.across + m.where(learn, across, 0.0)
            self.beta = m.clip(m.atan2(self.across, m.maximum(self.along, 1e-9)),
                               -self.max_angle, self.max_angle)
        return Estimate(est.x, est.y, m.wrap(est.yaw + self.beta), est.vx, est.vy, est.yaw_rate)
