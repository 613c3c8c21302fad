"""companion/live/health.py, pure: the estimate's health and who took the vehicle out of the
track mode, with each autopilot's facts from its profile."""

from __future__ import annotations

import math

import pytest

from companion.live import health
from companion.profiles import ardupilot, px4

AP, PX = ardupilot.PROFILE, px4.PROFILE


def watch(profile=AP, **kw):
    return health.EstimateWatch(profile.estimate, **kw)


@pytest.mark.parametrize("flags, words", [
    (0x33F, None),                                          # healthy on ArduPilot SITL
    (0x833F, "GPS glitching"),                              # the glitch (field-faults notes)
    (0x27, "no absolute horizontal position"),              # GPS lost, DCM
    (0x33F | 0x80, "constant-position mode"),
])
def test_ardupilot_flags(flags, words):
    w = watch()
    w.report(0x33F, {}, now=9.8)                            # healthy first: GPS had, then lost
    w.report(flags, {}, now=10.0)
    problem = w.problem(10.0)
    assert (problem is None) == (words is None)
    if words:
        assert words in problem and f"0x{flags:x}" in problem
        assert not w.healthy(10.0)


def test_absolute_position_counts_once_the_estimator_has_had_it():
    """A vehicle without GPS (its EKF never had an origin) flies a local mission; one that
    loses its absolute position pauses."""
    never = watch()
    for k in range(5):
        never.report(0x12F, {}, now=10.0 + 0.2 * k)        # relative position only, always
    assert never.problem(11.0) is None and never.healthy(20.0)
    lost = watch()
    lost.report(0x33F, {}, now=10.0)
    lost.report(0x12F, {}, now=10.2)
    assert "no absolute horizontal position" in (lost.problem(10.2) or "")


def test_the_glitch_bit_is_each_autopilots_own():
    """EKF_STATUS_REPORT's GPS glitch is 0x8000, ESTIMATOR_STATUS's 0x400."""
    a, p = watch(AP), watch(PX)
    a.report(0x33F | 0x400, {}, 0.0)
    p.report(0x33F | 0x400, {}, 0.0)
    assert a.problem(0.0) is None and "GPS glitching" in p.problem(0.0)
    assert PX.estimate.message == "ESTIMATOR_STATUS" and AP.estimate.message == "EKF_STATUS_REPORT"
    p.report(0x3FF, {"pos_horiz_ratio": 0.03, "vel_ratio": 0.03}, 1.0)   # PX4 SIH, healthy
    assert p.problem(1.0) is None


def test_a_variance_over_the_limit_and_a_nan_one_are_unhealthy():
    w = watch(variance_limit=0.8)
    w.report(0x33F, {"pos_horiz_variance": 0.3, "velocity_variance": 0.2}, 0.0)
    assert w.problem(0.0) is None
    w.report(0x33F, {"pos_horiz_variance": 0.95}, 0.1)
    assert "pos_horiz_variance 0.95 over 0.8" in w.problem(0.1)
    w.report(0x33F, {"velocity_variance": math.nan}, 0.2)
    assert "velocity_variance nan" in w.problem(0.2)


def test_healthy_again_only_after_healthy_for():
    w = watch(healthy_for=3.0)
    w.report(0x833F, {}, 1.0)
    w.report(0x33F, {}, 2.0)
    assert w.problem(2.0) is None           # nothing wrong now...
    assert not w.healthy(4.9)               # ...but not healthy for 3 s since 2.0
    assert w.healthy(5.0)
    w.report(0x833F, {}, 5.5)                # bad again: the clock starts over
    w.report(0x33F, {}, 5.6)
    assert not w.healthy(8.5) and w.healthy(8.6)


def test_steps_the_velocity_explains_are_not_steps():
    w = watch(step_limit=1.0)
    t, x, v = 0.0, 0.0, 4.0
    for _ in range(40):                      # steady 4 m/s, then braking at 2 m/s^2
        assert w.position(t, x, 0.0, v, 0.0, now=t) is None
        t += 0.025
        v2 = max(0.0, v - 0.05)
        x += 0.5 * (v + v2) * 0.025
        v = v2
    assert w.healthy(t)


def test_a_14_m_step_is_caught_and_held_for_healthy_for():
    w = watch(step_limit=1.0, healthy_for=3.0)
    assert w.position(0.0, 0.0, 0.0, 0.0, 0.0, now=0.0) is None
    step = w.position(0.025, 14.0, 0.0, 0.0, 0.0, now=0.025)
    assert step is not None and "stepped 14.00 m in 25 ms" in step
    assert w.problem(1.0) == step and not w.healthy(3.0) and w.healthy(3.03)
    assert w.position(0.05, 14.0, 0.0, 0.0, 0.0, now=0.05) is None    # no second step
    # a gap is not a step (the runner's segments handle gaps)
    assert w.position(5.0, 40.0, 0.0, 0.0, 0.0, now=5.0) is None


def fs(profile=AP):
    return health.FailsafeWatch(profile.failsafe)


def test_who_left_ardupilot():
    f = fs()
    # a mode change with nothing said: a pilot
    assert f.who_left("MANUAL", "HOLD", 0.0, False, False)[0] == health.PILOT
    # our own HOLD during our failsafe
    assert f.who_left("HOLD", "HOLD", 0.0, True, True)[0] == health.OURS
    # the EKF failsafe: its text, then the mode change
    assert f.text("EKF variance", 1.0) == "ekf"
    f.heartbeat(5)
    who, why = f.who_left("HOLD", "HOLD", 1.5, False, False)
    assert who == health.AUTOPILOT and "ekf failsafe" in why and '"EKF variance"' in why
    # ...even when we asked for HOLD ourselves (the autopilot's failsafe wins)
    assert f.who_left("HOLD", "HOLD", 1.5, True, True)[0] == health.AUTOPILOT
    # cleared: text and status
    assert f.text("EKF failsafe cleared", 20.0) is None
    f.heartbeat(4)
    assert f.cleared(20.0) and f.who_left("MANUAL", "HOLD", 21.0, False, False)[0] == health.PILOT


BATTERY = 0x2000000       # MAV_SYS_STATUS_SENSOR_BATTERY


def test_a_battery_bit_turning_unhealthy_names_the_battery_failsafe():
    f = fs()
    others = 0x1000000 | 0x20
    assert f.sys_status(others | BATTERY, others | BATTERY, 0.0) is None      # healthy
    assert f.sys_status(others, others, 1.0) is None          # not enabled: says nothing
    assert f.active(1.0) is None
    assert f.sys_status(others | BATTERY, others, 2.0) == "battery"         # healthy -> not
    who, why = f.who_left("HOLD", "HOLD", 2.1, False, False)
    assert who == health.AUTOPILOT and why.startswith("the autopilot's battery failsafe")
    assert f.sys_status(others | BATTERY, others, 3.0) is None     # still unhealthy: no news
    assert f.sys_status(others | BATTERY, others | BATTERY, 4.0) is None   # healthy again
    assert f.cleared(4.0)


def test_the_autopilots_words_stay_the_evidence_when_its_sys_status_follows():
    f = fs()
    f.sys_status(BATTERY, BATTERY, 0.0)
    assert f.text("Battery 1 is low 12.48V used 59 mAh", 1.0) == "battery"
    assert f.sys_status(BATTERY, 0, 1.03) == "battery"
    assert f.active(1.1) == ("battery", '"Battery 1 is low 12.48V used 59 mAh"')


def test_a_guided_timeout_does_not_make_a_later_pilot_the_autopilot():
    f = fs()
    f.text("target not received last 3secs, stopping", 0.0)
    assert f.active(1.0)[0] == "guided_timeout"
    assert f.who_left("MANUAL", "HOLD", 1.0, False, False)[0] == health.PILOT


def test_a_bare_critical_status_is_the_autopilots_failsafe():
    f = fs()
    f.heartbeat(5)
    who, why = f.who_left("RTL", "HOLD", 0.0, False, False)
    assert who == health.AUTOPILOT and "system_status critical" in why
    f.heartbeat(4)
    assert f.who_left("RTL", "HOLD", 0.0, False, False)[0] == health.PILOT


def test_failsafe_texts_age():
    f = fs()
    f.text("Battery 1 is low 10.2V", 0.0)
    assert f.active(health.TEXT_MEMORY)[0] == "battery"
    assert f.active(health.TEXT_MEMORY + 0.1) is None


def test_px4_offboard_loss_while_our_link_is_silent_is_the_link():
    f = fs(PX)
    f.heartbeat(5)                                 # PX4 turns critical on offboard loss
    assert f.who_left("LOITER", "LOITER", 0.0, True, True)[0] == health.LINK
    # with the link fine, the same is the autopilot's failsafe
    assert f.who_left("LOITER", "LOITER", 0.0, False, False)[0] == health.AUTOPILOT
    # a named failsafe while silent is still the autopilot's
    f.text("Failsafe: low battery", 1.0)
    assert f.who_left("LOITER", "LOITER", 1.0, True, True)[0] == health.AUTOPILOT
    # ArduPilot never leaves GUIDED on silence: HOLD while silent is ours
    a = fs(AP)
    assert a.who_left("HOLD", "HOLD", 0.0, True, True)[0] == health.OURS


def test_a_guided_timeout_text_says_our_setpoints_stopped_arriving():
    """ArduPilot stops the rover inside GUIDED when the setpoints stop for 3 s and says so:
    the companion's link is silent towards the vehicle. PX4's offboard loss leaves OFFBOARD
    instead, which its mode says (who_left), so its text is not read this way."""
    fs = health.FailsafeWatch(AP.failsafe)
    cause = fs.text("target not received last 3secs, stopping", now=1.0)
    assert cause == "guided_timeout" and fs.setpoints_lost(cause)
    assert not fs.setpoints_lost(fs.text("EKF failsafe", now=2.0))
    assert not fs.setpoints_lost(fs.text("Throttle armed", now=3.0))      # no cause at all
    px = health.FailsafeWatch(PX.failsafe)
    cause = px.text("Connection to offboard lost", now=1.0)
    assert cause in PX.failsafe.link_causes and not px.setpoints_lost(cause)


def test_a_clock_more_than_a_second_back_is_a_reboot():
    from companion.live.telemetry import RESTART_JUMP_MS, clock_went_back
    assert clock_went_back(70_000, 3_000)
    assert clock_went_back(70_000, 70_000 - RESTART_JUMP_MS - 1)
    assert not clock_went_back(70_000, 70_000 - RESTART_JUMP_MS)      # reordering, not a reboot
    assert not clock_went_back(70_000, 70_040)                        # the clock goes on
    assert not clock_went_back(None, 3_000)                           # nothing to compare with
