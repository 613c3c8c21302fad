"""companion.mission.coverage: the cross-track of positions against swaths (which samples count,
which side), the excursion, the share missed, and a cover placed as its mission is anchored."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.mission.coverage import FieldCover, cross_track, excursion, figures, missed_share

SWATHS = (((0.0, 0.0), (10.0, 0.0)), ((10.0, 1.0), (0.0, 1.0)))   # north, then back south
AREA = ((-0.5, -0.5), (10.5, -0.5), (10.5, 1.5), (-0.5, 1.5))
COVER = FieldCover(SWATHS, 1.0, AREA, ((-3.0, -3.0), (13.0, -3.0), (13.0, 4.0), (-3.0, 4.0)))


def test_samples_count_on_a_swath_interior_with_their_side():
    pts = [(5.0, 0.1),     # swath 0, 0.1 m east: right of a swath driven north
           (5.0, 0.9),     # swath 1, 0.1 m west of it: right of a swath driven south
           (0.5, 0.0),     # within 1 m of swath 0's end: not scored
           (5.0, 0.5),     # half a spacing from both: on neither
           (20.0, 0.0)]    # beyond the ends
    got = cross_track(pts, SWATHS, 1.0)
    assert got.ravel().tolist() == pytest.approx([0, 0.1, 1, 0.1])


def test_figures_say_the_lean_the_excursion_and_the_share_missed():
    # driven 2 cm to the left of each swath (west going north, east going south)
    pts = [(x, -0.02) for x in np.linspace(0, 10, 101)] + \
          [(x, 1.02) for x in np.linspace(10, 0, 101)] + [(0.0, -4.0)]   # and 1 m outside
    f = figures(pts, COVER)
    assert f["cross_track_p50"] == pytest.approx(0.02) and f["cross_track_max"] == pytest.approx(0.02)
    assert f["lean_out_back"] == pytest.approx([-0.02, -0.02])
    assert f["excursion"] == pytest.approx(1.0)
    assert f["on_swaths"] == 2 * 81 and f["samples"] == 203


def test_missed_share_is_the_area_no_tool_passed_over():
    full = missed_share([(x, y) for y in (0.0, 1.0) for x in (-0.5, 10.5)][:2] +
                        [(10.5, 1.0), (-0.5, 1.0)], AREA, 1.0)
    assert full == pytest.approx(0.0, abs=1e-9)
    half = missed_share([(-0.5, 0.0), (10.5, 0.0)], AREA, 1.0)   # one swath of two
    assert half == pytest.approx(0.5, abs=1e-3)
    assert missed_share([(0.0, 0.0)], AREA, 1.0) == 1.0
    assert excursion([(0.0, 0.0)], COVER.boundary) == 0.0


def test_a_cover_is_placed_as_its_mission_is_anchored():
    placed = COVER.placed(100.0, 50.0, math.pi / 2)    # turned to face east, moved
    (a, b) = placed.swaths[0]
    assert a == pytest.approx((100.0, 50.0)) and b == pytest.approx((100.0, 60.0))
    pts = [(100.1, 55.0)]                               # 0.1 m north of an eastward swath: left
    assert cross_track(pts, placed.swaths, 1.0).ravel().tolist() == pytest.approx([0, -0.1])
