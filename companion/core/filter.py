"""The model-free filter of Lee et al. (2024), eqs. (7)-(9) and (12)-(14), discretised exactly.

One second-order filter per channel (x, y and yaw), each the paper's system

    d/dt [q_hat, r_hat] = [[0, 1], [0, 0]] [q_hat, r_hat] + [l1, l2] (q - q_hat)

with the "nonlinearly structured" gains of eqs. (9) and (14):

    l1 = k_df + lambda_f,   l2 = k_df * lambda_f        (paper: l_{p_a,1}, l_{p_a,2})

so that the filtering error obeys e' = -lambda_f e + d_f, d_f' = -k_df d_f + q''
(Lemmas 1 and 3) and, once k_df is large, e' = -lambda_f e (Lemmas 2 and 4, eq. (15)).

Discretisation. The paper runs the filter at 1 kHz in continuous time; forward Euler there is
barely stable (k_df * dt = 1) and useless at the 10-50 Hz a real autopilot streams. Here each
step solves (7) exactly over the interval (t_prev, t] with the measurement held at its newest
value q_k (a zero-order hold of the sample that ends the interval, so the estimate reacts to a
sample the moment it arrives). In error coordinates w = [q_hat - q_k, r_hat] the system is
w' = A_L w with A_L = [[-l1, 1], [-l2, 0]], whose eigenvalues are -k_df and -lambda_f, hence

    w(t) = exp(A_L dt) w(t_prev)

and exp(A_L dt) has a closed form (Sylvester's formula, below). The step is exact for any dt,
so the filter steps on the measurement's own timestamps (variable dt) and is stable at any rate.

Yaw is unwrapped against the previous sample before filtering (a turn through +-pi is a small
step, not a 2 pi jump) and both the estimate and the unwrapped sample are shifted back by whole
turns afterwards, which leaves the linear dynamics untouched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from . import ops as _ops
from .angles import TAU, wrap
from .signals import Estimate, Measurement, Num


@dataclass(frozen=True)
class FilterGains:
    """Design parameters of the filter: ``k_df`` is the paper's k_{d,f}, ``lambda_f`` its lambda_f.

    Defaults are the paper's Section 5 values. Either may be a numpy array (one value per vehicle).
    """

    k_df: Num = 1000.0
    lambda_f: Num = 120.0

    @property
    def l1(self) -> Num:
        """Eq. (9)/(14): l_1 = k_df + lambda_f."""
        return self.k_df + self.lambda_f

    @property
    def l2(self) -> Num:
        """Eq. (9)/(14): l_2 = k_df * lambda_f."""
        return self.k_df * self.lambda_f


def transition(gains: FilterGains, dt: float, m: _ops.Ops = _ops.scalar) -> tuple[Num, Num, Num, Num]:
    """exp(A_L dt) = [[p11, p12], [p21, p22]] for A_L = [[-l1, 1], [-l2, 0]].

    With a = k_df and b = lambda_f (the eigenvalues are -a and -b), Sylvester's formula gives
    exp(A_L t) = (e^{-bt} (A_L + a I) - e^{-at} (A_L + b I)) / (a - b). Equal roots are moved
    apart by one part in 10^6, which changes the result by about 1e-10 instead of needing a
    second formula (and a branch that would not vectorise).
    """
    a = gains.k_df
    b = gains.lambda_f
    b = m.where(abs(a - b) < 1e-6 * a, b * (1.0 + 1e-6), b)
    ea = m.exp(-a * dt)
    eb = m.exp(-b * dt)
    inv = 1.0 / (a - b)
    p11 = (a * ea - b * eb) * inv
    p12 = (eb - ea) * inv
    p21 = a * b * (ea - eb) * inv
    p22 = (a * eb - b * ea) * inv
    return p11, p12, p21, p22


class PoseFilter:
    """The model-free filter on x, y (eqs. (7)-(9)) and yaw (eqs. (12)-(14)).

    ``n=None`` filters one vehicle on floats; ``n=k`` filters k vehicles held in numpy arrays
    (gains may then be arrays too). ``step`` takes the sample's own time stamp.
    """

    def __init__(self, gains: FilterGains = FilterGains(), n: int | None = None):
        self.gains = gains
        self.n = n
        self._m = _ops.for_size(n)
        self._dt: float | None = None
        self._phi: tuple[Num, Num, Num, Num] | None = None
        self.t: float | None = None

    @property
    def initialised(self) -> bool:
        return self.t is not None

    def reset(self, t: float, meas: Measurement) -> Estimate:
        """Start the filter at a sample: estimate = sample, rate states = 0."""
        zero = self._m.zeros(self.n)
        self.t = t
        self.x, self.y = meas.x + zero, meas.y + zero
        self._yaw_meas = wrap(meas.yaw) + zero   # previous yaw sample, unwrapped
        self.yaw = self._yaw_meas + 0.0
        self.vx = self.vy = self.yaw_rate = zero
        return self.estimate()

    def estimate(self) -> Estimate:
        return Estimate(self.x, self.y, wrap(self.yaw), self.vx, self.vy, self.yaw_rate)

    def step(self, t: float, meas: Measurement) -> Estimate:
        """Advance to the sample ``meas`` taken at time ``t`` (seconds; any spacing > 0)."""
        if self.t is None:
            return self.reset(t, meas)
        dt = t - self.t
        if not dt > 0.0:  # also catches NaN
            raise ValueError(f"filter time must increase: dt = {dt!r}")
        # Recompute exp(A_L dt) only when dt really changes: sample times like k * 0.001 differ
        # in the last bits from step to step, which would otherwise cost an exp per sample.
        if self._phi is None or self._dt is None or abs(dt - self._dt) > 1e-9 * dt:
            self._phi = transition(self.gains, dt, self._m)
            self._dt = dt
        p11, p12, p21, p22 = self._phi
        self.t = t

        ex = self.x - meas.x
        self.x = meas.x + p11 * ex + p12 * self.vx
        self.vx = p21 * ex + p22 * self.vx

        ey = self.y - meas.y
        self.y = meas.y + p11 * ey + p12 * self.vy
        self.vy = p21 * ey + p22 * self.vy

        yaw_meas = self._yaw_meas + self._m.wrap(meas.yaw - self._yaw_meas)
        eyaw = self.yaw - yaw_meas
        yaw = yaw_meas + p11 * eyaw + p12 * self.yaw_rate
        self.yaw_rate = p21 * eyaw + p22 * self.yaw_rate
        # Shift by whole turns so the states stay near (-pi, pi]; exact for linear dynamics.
        turns = TAU * self._m.floor((yaw_meas + math.pi) / TAU)
        self._yaw_meas = yaw_meas - turns
        self.yaw = yaw - turns
        return Estimate(self.x, self.y, self._m.wrap(self.yaw), self.vx, self.vy, self.yaw_rate)
