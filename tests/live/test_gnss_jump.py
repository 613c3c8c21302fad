"""Riding through a receiver's jump (companion.live.gnss_jump.JumpGuard): a step of the fixes
that the rover's own motion does not explain starts a ride on dead reckoning; the estimate is
handed back once the receiver has stepped back and the estimate has followed it back."""

from __future__ import annotations

import math

from companion.live.gnss_jump import JumpGuard

LAT0 = 47.0
EARTH = 6378137.0    # m: the fixes' flat earth here (the guard converts as ArduPilot does)
SPEED = 1.0          # m/s east
RATE, FIX = 40.0, 10.0


def fly(guard: JumpGuard, jump: float, at: float, until: float, slide: float = 0.7,
        seconds: float = 12.0):
    """A rover driving east at 1 m/s; the receiver jumps ``jump`` m north from ``at`` to
    ``until`` s; the estimate slides after it with time constant ``slide``. (t, steered y-error
    north of the truth, estimate's north error) at each estimate sample."""
    out, estimate_off = [], 0.0
    for k in range(int(seconds * RATE)):
        t = k / RATE
        target = jump if at <= t < until else 0.0
        estimate_off += (target - estimate_off) * (1 - math.exp(-1 / (RATE * slide)))
        east = SPEED * t
        if k % int(RATE / FIX) == 0:
            north = target
            lat = LAT0 + math.degrees(north / EARTH)
            lon = math.degrees(east / (EARTH * math.cos(math.radians(LAT0))))
            guard.fix(round(lat * 1e7), round(lon * 1e7), 0.014)
        x, y = guard.position(t, estimate_off, east, 0.0, SPEED)
        out.append((t, x, estimate_off))
    return out


def test_a_jump_is_ridden_through_and_the_estimate_handed_back_once_it_returned():
    g = JumpGuard()
    trace = fly(g, 0.25, at=3.0, until=7.0)
    # the steered position stays true: the estimate's slide over the one fix the jump takes to
    # be told from a late fix (0.25 m x (1 - exp(-0.1 / 0.7)) = 3.3 cm), handed back within
    # ``settle`` of the dead reckoning
    assert max(abs(x) for _, x, _ in trace) <= 0.035
    assert max(off for _, _, off in trace) > 0.24            # while the estimate went off
    assert g.jumps == 1 and g.riding_since is None            # handed back
    # back on the estimate once it has slid back (about 1.5 s after the receiver) and the
    # dead reckoning's drift has faded out (blend_s)
    t_back = next(t for t, x, off in trace if t > 7.0 and x == off)
    assert t_back < 7.0 + 1.7 + g.blend_s


def test_a_rover_speeding_up_is_no_jump():
    g = JumpGuard()
    for k in range(400):
        t = k / RATE
        v = min(5.0, 10.0 * t)                       # 10 m/s^2 up to 5 m/s
        east = 5.0 * t - 1.25 if t > 0.5 else 5.0 * t * t
        if k % 4 == 0:
            lon = math.degrees(east / (EARTH * math.cos(math.radians(LAT0))))
            g.fix(round(LAT0 * 1e7), round(lon * 1e7), 0.014)
        g.position(t, 0.0, east, 0.0, v)
    assert g.jumps == 0


def test_one_fix_off_is_a_late_one_not_a_jump():
    g = JumpGuard()
    fly(g, 0.25, at=3.0, until=3.05)
    assert g.jumps == 0 and g.riding_since is None


def test_a_jump_that_never_returns_is_overdue_after_max_ride():
    g = JumpGuard(max_ride=4.0)
    fly(g, 0.25, at=3.0, until=99.0, seconds=7.5)
    assert g.riding_since is not None and g.overdue(7.5) and not g.overdue(6.9)
    g.forget()
    assert g.riding_since is None and not g.overdue(8.0)


def test_plain_gps_is_not_judged():
    g = JumpGuard()
    lon = round(math.degrees(1.0 / (EARTH * math.cos(math.radians(LAT0)))) * 1e7)
    g.position(0.0, 0.0, 0.0, 0.0, 0.0)
    for k in range(20):
        assert g.fix(round(LAT0 * 1e7) + k % 2 * 50, lon, 0.7) is None   # 0.55 m steps
    assert g.riding_since is None


def test_back_in_its_class_after_float_the_receiver_is_steered_by_until_the_estimate_agrees():
    """Float (h_acc 0.4: not judged) from 3 to 6 s: the estimate wanders 0.3 m north with it;
    fixed again at 6 s, the receiver is right at once while the estimate slides back over about
    a second: the steered position follows the receiver, then the estimate once they agree."""
    g = JumpGuard()
    out, est = [], 0.0
    for k in range(int(12 * RATE)):
        t = k / RATE
        floating = 3.0 <= t < 6.0
        target = 0.3 if floating else 0.0
        est += (target - est) * (1 - math.exp(-1 / (RATE * 0.7)))
        east = SPEED * t
        if k % 4 == 0:
            north = 0.3 if floating else 0.0
            lat = LAT0 + math.degrees(north / EARTH)
            lon = math.degrees(east / (EARTH * math.cos(math.radians(LAT0))))
            g.fix(round(lat * 1e7), round(lon * 1e7), 0.4 if floating else 0.014)
        x, _ = g.position(t, est, east, 0.0, SPEED)
        out.append((t, x, est))
    after = [(t, x, e) for t, x, e in out if 6.15 <= t < 7.5]
    assert max(e for _, _, e in after) > 0.1                   # the estimate is still off
    assert max(abs(x) for _, x, _ in after) < 0.02             # the steered position is not
    assert not g.steering() and out[-1][1] == out[-1][2]       # handed back by the end


def test_the_lag_fit_over_a_sliding_window_is_the_least_squares_one():
    """LagWindow's running sums give the fit a least-squares solve of the window's pairs gives,
    after the window has turned over several times (pairs dropped, sums rebuilt)."""
    import numpy as np

    from companion.live.gnss_jump import LagWindow

    rng = np.random.default_rng(3)
    window = LagWindow(60)
    pairs = []
    for k in range(437):
        vn, ve = math.cos(k / 30), math.sin(k / 30)
        pair = (0.3 - 0.12 * vn + rng.normal(0, 0.01), -0.2 - 0.12 * ve + rng.normal(0, 0.01),
                vn, ve)
        window.add(*pair)
        pairs.append(pair)
    last = np.array(pairs[-60:])
    # d_n = c_n - lag v_n, d_e = c_e - lag v_e: unknowns (c_n, c_e, lag)
    a = np.block([[np.ones((60, 1)), np.zeros((60, 1)), -last[:, 2:3]],
                  [np.zeros((60, 1)), np.ones((60, 1)), -last[:, 3:4]]])
    want = np.linalg.lstsq(a, np.concatenate([last[:, 0], last[:, 1]]), rcond=None)[0]
    lag = window.lag()
    assert lag is not None and len(window) == 60
    got = (*window.offset(lag), lag)
    assert np.allclose(got, want, atol=1e-9), (got, want)
    assert abs(got[2] - 0.12) < 0.01


def test_the_lag_fit_names_no_lag_when_the_velocity_does_not_vary():
    import numpy as np

    from companion.live.gnss_jump import LagWindow

    window = LagWindow(10)
    for _ in range(10):
        window.add(0.1, 0.2, 1.0, 0.0)
    assert window.lag() is None and np.allclose(window.offset(0.0), (0.1, 0.2))
