"""One inner-loop channel (speed or turn rate) over a step, exactly: the rate-limited first-order
lag (:func:`channel`), the overshoot of a loop with two time scales (:func:`overshoot_step`,
:func:`overshoot_integral`) and the motors' cap on an overshooting turn rate
(:func:`turn_rate_cap`). The equations are :mod:`companion.sim.plant`'s module docstring; the
rover model, the fit's channels (:mod:`companion.ident.channels`) and
:mod:`companion.sim.response` all step their channels here.
"""

from __future__ import annotations

import numpy as np

from ..core import ops as _ops
from ..core.signals import Num


def turn_rate_cap(m: _ops.Ops, w0: Num, w_mid: Num, w_end: Num, i_mid: Num, i_end: Num,
                  g: Num, top: Num, h: float) -> tuple[Num, Num, Num, Num]:
    """The overshooting turn rate (``yaw_overshoot`` g != 0) capped at ``top``, the turn-rate
    range the state leaves (:meth:`companion.sim.plant.RoverModel.tops`): the rate loop's
    feed-forward can drive the motors past its target, not past what the motors give. A
    skid-steer rover at speed has less steering left (the mixer shares one range), so the
    overshoot a fast rover would have is cut where a slow one shows it whole (measured:
    docs/design/vehicle-model.md, the motors' cap). Returns (omega at h/2, at h, the heading's
    change to each): where the cap cuts either, the heading takes the quadratic through omega
    at 0, h/2 and h (Simpson's rule and its half-step form) in place of the exact integral,
    which is of the uncapped rate. The lag behind (x, z) runs on uncapped, as the fit's
    (:func:`companion.sim.lag_series.lag_series`, ``capped``)."""
    c_mid, c_end = cap_overshoot(m, w_mid, g, top), cap_overshoot(m, w_end, g, top)
    cut = (c_mid != w_mid) | (c_end != w_end)
    if not np.any(cut):             # the usual case: nothing capped, the exact integrals stand
        return w_mid, w_end, i_mid, i_end
    q_mid = h / 24.0 * (5.0 * w0 + 8.0 * c_mid - c_end)
    q_end = h / 6.0 * (w0 + 4.0 * c_mid + c_end)
    return c_mid, c_end, m.where(cut, q_mid, i_mid), m.where(cut, q_end, i_end)


def cap_overshoot(m: _ops.Ops, w: Num, g: Num, top: Num) -> Num:
    """A turn rate ``w`` with a two-time-scale share ``g`` within +-``top`` (where g is 0 the
    rate is the lag's own, within the clamp already, and left as it is)."""
    return m.where(g != 0, m.clip(w, -top, top), w)


def overshoot_target(v: Num, z: Num, g: Num) -> Num:
    """The speed channel's inner output x behind a speed v with overshoot state z:
    v = (1 + g) x - g z."""
    return (v + g * z) / (1.0 + g)


def overshoot_step(m: _ops.Ops, x0: Num, x1: Num, z0: Num, g: Num, tau: Num, t: float) -> tuple[Num, Num]:
    """(speed, z) ``t`` s on, x having gone from x0 to x1 (linearly, as over one step).

    ArduPilot's speed loop with a throttle feed-forward that over-drives the motors (SITL
    ``rover`` on rover.parm: CRUISE_THROTTLE 30 % gives 6 m/s, CRUISE_SPEED says 5) and a PI
    that takes the excess back: the speed overshoots each change of the rate-limited target x by
    a share g, and returns to it as z catches up, ``z' = (x - z) / tau``, so
    ``v = x + g (x - z)`` (a lead-lag (1 + (1 + g) tau s) / (1 + tau s) on x). z over the step
    with x taken at its mean (a step is at most a tick, tau about a second)."""
    k = 1.0 - m.exp(-t / tau)
    z1 = z0 + k * (0.5 * (x0 + x1) - z0)
    return (1.0 + g) * x1 - g * z1, z1


def lag_step(m: _ops.Ops, x: Num, z: Num, u: Num, b: Num, up: Num, down: Num, dt: float,
             g: Num, tau: Num, over: bool, cap: Num = None) -> tuple[Num, Num, Num]:
    """One grid step of a channel for the fit and :mod:`companion.sim.response`: the
    rate-limited lag's output x from ``x`` towards ``u`` (:func:`channel`), then, ``over``,
    its overshoot (:func:`overshoot_step`), capped at ``cap`` where g != 0 (the turn rate's:
    :func:`turn_rate_cap`; None: no cap, the speed's). Returns (what is measured, x, z)."""
    # x(h) only: the fit's step loop spends most of its time here, and the integrals (unused
    # here) were a third of it (docs/design/vehicle-model.md)
    _, x1, _, _ = channel(m, x, u, b, up, down, dt, both=False, integrals=False)
    if not over:
        return x1, x1, z
    y, z1 = overshoot_step(m, x, x1, z, g, tau, dt)
    if cap is not None:
        y = cap_overshoot(m, y, g, cap)
    return y, x1, z1


def overshoot_integral(x0: Num, x1: Num, x_integral: Num, z0: Num, g: Num, tau: Num, t: float,
                       m: _ops.Ops) -> Num:
    """The integral over ``t`` s of the output ``(1 + g) x - g z`` of :func:`overshoot_step`,
    given the channel's own integral of x: z as that function has it (x at its mean,
    ``z(s) = xm + (z0 - xm) e^{-s / tau}``), so the heading and the turn rate agree."""
    xm = 0.5 * (x0 + x1)
    z_integral = xm * t - (xm - z0) * tau * (1.0 - m.exp(-t / tau))
    return (1.0 + g) * x_integral - g * z_integral


def rate_bounds(m: _ops.Ops, x: Num, up: Num, down: Num) -> tuple[Num, Num]:
    """(lowest, highest) rate of change for a channel at ``x``: ``up`` while |x| grows, ``down``
    while it shrinks (at x = 0 both directions grow)."""
    lo = m.where(x > 0, -down, -up)
    hi = m.where(x < 0, down, up)
    return lo, hi


def channel(m: _ops.Ops, x0: Num, u: Num, b: Num, up: Num, down: Num, h: float,
             both: bool = True, integrals: bool = True) -> tuple[Num, Num, Num, Num]:
    """One channel over a step with its input ``u`` held: x' = clip(b (u - x), rate bounds).

    Exact: x ramps at the limit L (``up`` or ``down``, by the direction of travel at the start)
    for t1 = (|e0| - L / b) / L while the lag would ask more than L, then decays as
    u - e1 exp(-b (t - t1)) with |e1| = L / b. Returns x(h/2), x(h) and their integrals from 0
    (``both=False``: x(h) only, the others None; ``integrals=False``: no integrals).
    (A ramp that crosses zero keeps the limit it started with: a step is a millisecond or so.)
    """
    e0 = u - x0
    limit = up if down is up else m.where(e0 * x0 < 0, down, up)
    knee = limit / b                                  # |error| below which the lag is unclipped
    t1 = m.maximum(abs(e0) / limit - 1.0 / b, 0.0)    # = (|e0| - knee) / L; 0 with no limit
    e1 = m.clip(e0, -knee, knee)                      # the error when the ramp ends
    ramp = m.where(t1 > 0, m.where(e0 < 0, -limit, limit), 0.0)   # 0: no inf * 0
    out = []
    for t in ((0.5 * h, h) if both else (h,)):
        tr = m.minimum(t, t1)                          # time spent ramping
        te = t - tr                                    # then decaying
        decay = m.exp(-b * te)
        x = m.where(te > 0, u - e1 * decay, x0 + ramp * tr)
        integral = (x0 * tr + 0.5 * ramp * tr * tr + (u * te - e1 * (1.0 - decay) / b)
                    if integrals else None)
        out += [x, integral]
    if not both:
        return None, out[0], None, out[1]
    return out[0], out[2], out[1], out[3]
