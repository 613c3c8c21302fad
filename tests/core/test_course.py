"""The course correction (companion.core.course): beta-hat learns the angle from the reported
heading to the direction of travel, and the PZC law steering the course removes the sideways
offset that angle leaves on a curved path."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.core.course import MAX_ANGLE, CourseCorrection
from companion.core.filter import FilterGains
from companion.core.pzc import PZCGains, PZCTracker
from companion.core.signals import Estimate, Measurement
from companion.core.trajectory import Ellipse

DT = 0.025


class Drive:
    """Filtered poses of a rover heading ``yaw`` while it moves along ``course``."""

    def __init__(self) -> None:
        self.x = self.y = 0.0

    def __call__(self, yaw: float, course: float, speed: float = 2.0) -> Estimate:
        self.x += speed * DT * math.cos(course)
        self.y += speed * DT * math.sin(course)
        return Estimate(self.x, self.y, yaw, 0.0, 0.0, 0.0)


def test_learns_the_angle_at_its_time_constant():
    c, moving = CourseCorrection(tau=2.0), Drive()
    for k in range(int(20.0 / DT)):                     # along the heading: nothing to learn
        c.step(k * DT, moving(0.3, 0.3))
    assert c.beta == pytest.approx(0.0, abs=1e-12)
    k0 = int(20.0 / DT)
    for k in range(k0, k0 + int(2.0 / DT)):             # then 0.05 rad off it, one tau
        c.step(k * DT, moving(0.3, 0.35))
    assert c.beta == pytest.approx(0.05 * (1 - math.exp(-1)), rel=0.03)
    for k in range(k0 + int(2.0 / DT), k0 + int(30.0 / DT)):
        out = c.step(k * DT, moving(0.3, 0.35))
    assert c.beta == pytest.approx(0.05, abs=1e-5)
    assert out.yaw == pytest.approx(0.35, abs=1e-5)     # the law sees the course


def test_position_noise_averages_out_over_the_distance():
    """5 mm of position noise at 40 Hz and 1.6 m/s: each step's course is uncertain by about
    0.2 rad, the estimate by well under a hundredth of that."""
    rng = np.random.default_rng(3)
    c, moving = CourseCorrection(tau=2.0), Drive()
    betas = []
    for k in range(int(60.0 / DT)):
        clean = moving(1.0, 1.03, speed=1.6)
        noisy = Estimate(clean.x + rng.normal(0, 0.005), clean.y + rng.normal(0, 0.005),
                         1.0 + rng.normal(0, 0.002), 0.0, 0.0, 0.0)
        c.step(k * DT, noisy)
        if k * DT > 10.0:
            betas.append(c.beta)
    assert np.mean(betas) == pytest.approx(0.03, abs=0.001)
    assert np.std(betas) < 0.003


def test_holds_when_slow_or_reversing_and_clips_transients():
    c, moving = CourseCorrection(tau=1.0), Drive()
    for k in range(200):
        c.step(k * DT, moving(0.0, 0.1))
    learned = c.beta
    for k in range(200, 400):                   # creeping: the course is noise
        c.step(k * DT, moving(0.0, 1.0, speed=0.2))
    for k in range(400, 600):                   # reversing: velocity opposite the heading
        c.step(k * DT, moving(0.0, math.pi - 0.1))
    assert c.beta == pytest.approx(learned)
    for k in range(600, 1200):                  # a sideways skid far past MAX_ANGLE
        c.step(k * DT, moving(0.0, 1.2))
    assert c.beta == pytest.approx(MAX_ANGLE, abs=1e-6)


def test_off_is_the_identity_and_wraps_across_pi():
    off, moving = CourseCorrection(tau=0.0), Drive()
    est = moving(3.1, 2.5)
    assert off.step(0.0, est) is est
    c = CourseCorrection(tau=0.5)
    for k in range(400):
        out = c.step(k * DT, moving(3.1, 3.1 + 0.1 - 2 * math.pi))   # course past +pi
    assert c.beta == pytest.approx(0.1, abs=1e-4)
    assert out.yaw == pytest.approx(3.2 - 2 * math.pi, abs=1e-4)


def test_arrays_match_scalars():
    yaws, courses = np.array([0.0, 1.0, -2.0]), np.array([0.05, 0.9, -2.2])
    batch = CourseCorrection(tau=np.array([1.0, 2.0, 0.0]), n=3)
    singles = [CourseCorrection(tau=tau) for tau in (1.0, 2.0, 0.0)]
    drives = [Drive() for _ in range(3)]
    for k in range(100):
        one = [s.step(k * DT, d(y, c))
               for s, d, y, c in zip(singles, drives, yaws, courses, strict=True)]
        out = batch.step(k * DT, Estimate(np.array([e.x for e in one]),
                                          np.array([e.y for e in one]), yaws, np.zeros(3),
                                          np.zeros(3), np.zeros(3)))
    np.testing.assert_allclose(out.yaw, [e.yaw for e in one], atol=1e-12)
    assert batch.beta[2] == 0.0
    np.testing.assert_allclose(batch.beta, [0.05, -0.1, 0.0], atol=1e-9)


def _fly(course_tau: float, slip: float, f_r: float = 0.08) -> tuple[float, float]:
    """A unicycle whose velocity is ``slip`` rad off its heading, tracking the paper's ellipse
    at 40 Hz with first-order inner loops: (steady RMS, mean signed cross-track error)."""
    ref_traj = Ellipse.paper(f_r)
    gains = PZCGains(k_dc=1.0, lambda_c=0.5, k_dc_yaw=2.0, lambda_c_yaw=1.0, velocity_ff=True,
                     heading_rate_ff=True, course_tau=course_tau)
    tracker = PZCTracker(FilterGains(700.0, 300.0), gains)
    first = ref_traj.sample(0.0)
    x, y, yaw = first.x, first.y, math.atan2(first.vy, first.vx)
    v = w = 0.0
    errors, cross = [], []
    n = int(60.0 / DT)
    for k in range(n):
        t = k * DT
        ref = ref_traj.sample(t)
        cmd = tracker.step(t, Measurement(x, y, yaw), ref)
        for _ in range(5):                       # the plant at 200 Hz, inner loops at 10 rad/s
            h = DT / 5
            v += (cmd.speed - v) * (1 - math.exp(-10 * h))
            w += (cmd.yaw_rate - w) * (1 - math.exp(-10 * h))
            x += v * math.cos(yaw + slip) * h
            y += v * math.sin(yaw + slip) * h
            yaw += w * h
        if t >= 30.0:
            ex, ey = ref.x - x, ref.y - y
            errors.append(ex * ex + ey * ey)
            speed = math.hypot(ref.vx, ref.vy)
            cross.append((-ex * ref.vy + ey * ref.vx) / speed)
    return math.sqrt(sum(errors) / len(errors)), sum(cross) / len(cross)


def test_steering_the_course_removes_the_sideways_offset():
    slip = 0.03                                  # what ArduPilot SITL shows at 0.08 Hz
    rms_heading, cross_heading = _fly(0.0, slip)
    rms_course, cross_course = _fly(2.0, slip)
    rms_clean, _ = _fly(0.0, 0.0)
    assert abs(cross_heading) > 0.03             # the heading law runs ~v beta / K_P aside
    assert abs(cross_course) < 0.2 * abs(cross_heading)
    assert rms_course < rms_heading - 0.002
    assert rms_course < rms_clean + 0.001        # as if there were no slip
    # and without slip the correction changes nothing that matters
    assert _fly(2.0, 0.0)[0] == pytest.approx(rms_clean, rel=0.02)
