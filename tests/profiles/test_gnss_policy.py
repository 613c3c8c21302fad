"""The GNSS policy (companion.profiles.gnss): what a drop in the receiver's class does,
relative to the class the run began with."""

from __future__ import annotations

import pytest

from companion import profiles
from companion.profiles import gnss
from companion.profiles.gnss import CONTINUE, HOLD, SLOW, GnssPolicy

NO_GPS, NO_FIX, FIX_2D, FIX_3D, DGPS, FLOAT, FIXED, PPP = 0, 1, 2, 3, 4, 5, 6, 8
P = GnssPolicy()


@pytest.mark.parametrize("start, now, want", [
    (FIXED, FIXED, CONTINUE),
    (FIXED, FLOAT, HOLD),           # ArduPilot #8787: only RTK fixed is trusted
    (FIXED, DGPS, HOLD),
    (FIXED, FIX_3D, HOLD),
    (FIXED, NO_FIX, HOLD),
    (FLOAT, FIXED, CONTINUE),       # better than the run's: carry on
    (FLOAT, FLOAT, CONTINUE),
    (FLOAT, DGPS, SLOW),
    (DGPS, FIX_3D, SLOW),
    (PPP, FIX_3D, SLOW),
    (FIX_3D, FIX_3D, CONTINUE),
    (FIX_3D, FIX_2D, HOLD),         # no usable fix whatever the run began with
    (FIX_3D, NO_GPS, HOLD),
    (NO_GPS, NO_GPS, CONTINUE),     # a run begun without GNSS does not steer by it
    (NO_FIX, NO_GPS, CONTINUE),
])
def test_the_action_for_each_drop(start, now, want):
    assert gnss.action(P, start, now) == want


def test_a_policy_is_data_an_autopilot_may_change():
    lenient = GnssPolicy(from_rtk_fixed=SLOW)
    assert gnss.action(lenient, FIXED, FLOAT) == SLOW
    assert gnss.action(lenient, FIXED, NO_FIX) == HOLD


def test_every_autopilot_has_a_policy():
    for p in profiles.AUTOPILOTS.values():
        assert isinstance(p.gnss, GnssPolicy) and 0 < p.gnss.slow_factor < 1


def test_what_to_expect_names_the_class_and_the_claimed_accuracy():
    rtk = gnss.expectation(FIXED, 0.014)
    assert "RTK fixed" in rtk and "0.01 m" in rtk and "holds" in rtk
    plain = gnss.expectation(FIX_3D, 0.7)
    assert "3D fix" in plain and "0.7 m" in plain and "cannot remove it" in plain
    assert "claims no accuracy" in gnss.expectation(FIX_3D, None)
    assert gnss.name(42) == "fix type 42" and gnss.rank(42) == 0
