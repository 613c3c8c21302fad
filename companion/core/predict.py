"""Delay prediction: the law sees where the rover will be once its speed commands land (an
extension beyond the paper, a Smith predictor on the position).

A speed loop that answers only after a pure delay d (ArduPilot's car, SITL ``--model rover``:
0.5 s) puts d inside the position loop: whatever the law asks now moves the rover d later, and
a loop tuned around that lag gives up most of its gain at 0.08 Hz. The commands of the last d
seconds are known, though: they are what the rover will drive over the next d. So this stage
moves the filtered position along them and compares it with the reference d ahead,

    p_pred = p_hat + sum_k v_k dt_k [cos, sin](phi_hat + omega_last s_k)
    p_ref(t + d) ~ p_ref + d p_ref' + d^2 / 2 p_ref''       (its velocity: p_ref' + d p_ref'')

where v_k is the speed command sent at t_k, applied over [t_k + d, t_(k+1) + d) ∩ [t, t + d)
for dt_k seconds from s_k on, and the heading turns on at the last yaw-rate command sent
(omega_last). The heading itself is left as measured. Only the speed is taken from a law run on
this prediction: the turn rate lands at once, so it comes from the law on the present
(:class:`companion.core.pzc.PZCTracker`; a single law on the prediction steered d early and cut
the corners). The speed then acts on a loop without the delay (the Smith predictor's idea,
without its model of the lag: what the vehicle's lag leaves is the law's to correct).
``horizon = 0`` (the default) passes everything through. Floats (one vehicle) or arrays
(batch), no clock.
"""

from __future__ import annotations

import numpy as np

from . import ops as _ops
from .signals import Command, Estimate, Num, Reference


class DelayPrediction:
    def __init__(self, horizon: Num, n: int | None = None):
        self.horizon, self.n = horizon, n
        self._m = _ops.for_size(n)
        self.active = not _ops.is_plain_zero(horizon)
        self._longest = float(max(_flat(horizon))) if self.active else 0.0
        # Lanes (batch) ordered by horizon, longest first: a command sent at t_k still acts in
        # lane i while t_(k+1) > t - horizon_i, so the lanes it acts in are a prefix of this
        # order and the sum below visits only those: a loop over every lane dominated a car's
        # robust tune (measured: docs/design/pzc-extensions.md).
        lanes = self.active and n is not None and np.ndim(horizon) == 1
        self._order = np.argsort(-np.asarray(horizon), kind="stable") if lanes else None
        if self._order is not None:
            self._sorted = np.asarray(horizon, dtype=float)[self._order]
            self._neg_sorted = -self._sorted                    # ascending, for searchsorted
        self.reset()

    def reset(self) -> None:
        self._sent: list[tuple[float, Num]] = []     # (time, speed command) of the last horizon
        self._rate: Num = self._m.zeros(self.n)      # the last yaw-rate command

    def step(self, t: float, est: Estimate, ref: Reference) -> tuple[Estimate, Reference]:
        """The pose the commands in flight lead to, and the reference at that time."""
        if not self.active:
            return est, ref
        m, h = self._m, self.horizon
        # Forget what has landed for every lane (sent more than the longest horizon ago).
        while len(self._sent) > 1 and self._sent[1][0] <= t - self._longest:
            self._sent.pop(0)
        if self._order is not None and self._sent:
            dx, dy = self._travel_lanes(t, est.yaw)
        else:
            dx = dy = 0.0
            ends = [tk for tk, _ in self._sent[1:]] + [t] if self._sent else []
            for (tk, speed), end_k in zip(self._sent, ends, strict=True):
                dur, mid = _acting(m, tk - t, end_k - t, h)
                heading = est.yaw + self._rate * mid
                dx = dx + speed * dur * m.cos(heading)
                dy = dy + speed * dur * m.sin(heading)
        half = 0.5 * h * h
        ahead = Reference(ref.x + h * ref.vx + half * ref.ax, ref.y + h * ref.vy + half * ref.ay,
                          ref.vx + h * ref.ax, ref.vy + h * ref.ay, ref.ax, ref.ay)
        return Estimate(est.x + dx, est.y + dy, est.yaw, est.vx, est.vy, est.yaw_rate), ahead

    def _travel_lanes(self, t: float, yaw: Num) -> tuple[Num, Num]:
        """The same sum for lanes of their own horizons, each command over the lanes it still
        acts in (a prefix of the horizon order; the others would add exact zeros), in the
        order sent: the same numbers as the loop above, lane by lane."""
        order, h = self._order, self._sorted
        assert order is not None             # only lanes of their own horizons come here
        yaw = np.broadcast_to(yaw, order.shape)[order]
        rate = np.broadcast_to(self._rate, order.shape)[order]
        dx, dy = np.zeros(order.size), np.zeros(order.size)
        ends = [tk for tk, _ in self._sent[1:]] + [t]
        for (tk, speed), end_k in zip(self._sent, ends, strict=True):
            c = int(np.searchsorted(self._neg_sorted, end_k - t))    # lanes with h > t - end_k
            if c == 0:
                continue
            dur, mid = _acting(_ops.array, tk - t, end_k - t, h[:c])
            heading = yaw[:c] + rate[:c] * mid
            dx[:c] += speed[:c] * dur * np.cos(heading)
            dy[:c] += speed[:c] * dur * np.sin(heading)
        out_x, out_y = np.empty_like(dx), np.empty_like(dy)
        out_x[order], out_y[order] = dx, dy
        return out_x, out_y

    def sent(self, t: float, cmd: Command) -> None:
        """Record what left at ``t`` (after every clamp): it lands ``horizon`` later."""
        if self.active:
            speed = cmd.speed
            if self._order is not None:      # kept in the horizon order (_travel_lanes)
                speed = np.broadcast_to(speed, self._order.shape)[self._order]
            self._sent.append((t, speed))
            self._rate = cmd.yaw_rate


def _acting(m: _ops.Ops, sent: Num, next_sent: Num, h: Num) -> tuple[Num, Num]:
    """How long a command sent ``sent`` s from now (<= 0), and replaced ``next_sent`` s from
    now, acts within the next ``h`` s once it lands ``h`` late, and the middle of that time."""
    start = m.maximum(sent + h, 0.0)          # s from now when it starts to act ...
    end = m.minimum(next_sent + h, h)         # ... and when the next one takes over
    return m.maximum(end - start, 0.0), 0.5 * (start + end)


def _flat(value: Num) -> list[float]:
    try:
        return [float(v) for v in value]
    except TypeError:
        return [float(value)]
