"""The pure parts of the live loop: telemetry checks, run statistics, settings precedence."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from companion import mission as missions
from companion.core.filter import FilterGains
from companion.core.limits import DEFAULT_LIMITS, Limits
from companion.core.pzc import PZCGains
from companion.errors import UserError
from companion.live.policy import GainOptions, KnownVehicle, choose_gains, choose_limits, requested_rate
from companion.live.stats import LatencyHistogram, TrackingStats
from companion.live.telemetry import TelemetryCheck


class Msg(SimpleNamespace):
    def get_srcSystem(self):
        return self.sysid

    def get_srcComponent(self):
        return self.compid


def att(ms, yaw=0.1, sysid=1, compid=1, yawspeed=0.0):
    return Msg(time_boot_ms=ms, yaw=yaw, yawspeed=yawspeed, sysid=sysid, compid=compid)


def pos(ms, x=1.0, y=2.0, vx=0.0, vy=0.0, sysid=1, compid=1):
    return Msg(time_boot_ms=ms, x=x, y=y, vx=vx, vy=vy, sysid=sysid, compid=compid)


def test_good_samples_pair_position_with_the_newest_attitude():
    t = TelemetryCheck(1, 1)
    t.attitude(att(100, yaw=0.5))
    s = t.position(pos(100))
    assert (s.t, s.x, s.y, s.yaw) == (0.1, 1.0, 2.0, 0.5)
    t.attitude(att(125, yaw=0.6))
    assert t.position(pos(125)).yaw == 0.6
    assert t.accepted == 2 and t.rejected_total == 0


@pytest.mark.parametrize("bad, reason", [
    (pos(125, x=math.nan), "not_finite"), (pos(125, vy=math.inf), "not_finite"),
    (pos(100), "duplicate"), (pos(99), "time_backwards"),
    (pos(125, sysid=2), "other_source"), (pos(125, compid=5), "other_source"),
])
def test_bad_samples_are_refused_and_counted(bad, reason):
    t = TelemetryCheck(1, 1)
    t.attitude(att(100))
    assert t.position(pos(100)) is not None
    t.attitude(att(125))
    assert t.position(bad) is None
    assert t.rejected[reason] == 1 and t.rejected_total == 1
    assert t.position(pos(150)) is not None     # the next good one still passes


def test_a_bad_attitude_blocks_positions_until_a_good_one():
    t = TelemetryCheck(1, 1)
    t.attitude(att(100))
    t.attitude(att(125, yaw=math.nan))
    assert t.position(pos(125)) is None
    assert t.rejected == {**t.rejected, "not_finite": 1, "no_attitude": 1}
    t.attitude(att(150))
    assert t.position(pos(150)) is not None


def test_stale_attitude_and_reboot_streak():
    t = TelemetryCheck(1, 1, max_attitude_age=0.5)
    t.attitude(att(1000))
    assert t.position(pos(1600)) is None and t.rejected["no_attitude"] == 1
    t.attitude(att(5000))
    assert t.position(pos(5000)) is not None
    for ms in (40, 65, 90):                      # the vehicle rebooted
        t.attitude(att(ms))
        assert t.position(pos(ms)) is None
    assert t.backwards_streak == 3 and t.rejected["time_backwards"] == 3


def test_latency_histogram():
    h = LatencyHistogram()
    for us in range(1, 101):
        h.add(us * 1e-6)
    assert h.percentile(50) == pytest.approx(50e-6, abs=1.1e-6)
    assert h.percentile(99) == pytest.approx(99e-6, abs=1.1e-6)
    assert h.max_s == pytest.approx(100e-6)
    h.add(5.0)                                    # beyond the last bin
    assert h.percentile(100) == 5.0
    assert math.isnan(LatencyHistogram().percentile(50))


def test_tracking_stats_trapezoid_steady_and_missed():
    st = TrackingStats(duration=4.0, period=1.0)
    for k, e2 in enumerate([4.0, 0.0, 1.0]):
        st.add(float(k), float(k), e2, 1e-4, backlog=False)
    assert st.f_cost == pytest.approx(math.sqrt(2.0 + 0.5))
    assert st.steady_rms == pytest.approx(math.sqrt(1.0))   # only t = 2 is in the second half
    st.add(5.0, 5.0, 0.0, 2.0, backlog=True)                # two periods skipped, an overrun
    assert st.gaps == 2 and st.overruns == 1 and st.backlog == 1
    assert st.f_cost == pytest.approx(math.sqrt(2.5 + 1.5))
    st.segment_start()
    st.add(5.0, 9.0, 1.0, 1e-4, backlog=False)              # no integration across a pause
    assert st.f_cost == pytest.approx(2.0)


def _gains(mission, rate, **kw):
    return choose_gains(mission, GainOptions(**kw), KnownVehicle(), rate)


def test_gain_precedence(tmp_path):
    paper = missions.paper_ellipse()
    # nothing given: shipped tuned gains for (rate, w_c, d_cen) if any, else the paper's
    choice = _gains(paper, 40.0)
    if choice.source == "paper":
        assert choice.filter == FilterGains() and choice.pzc == PZCGains()
    g = tmp_path / "g.toml"
    g.write_text("rate_hz = 25.0\n[filter]\nk_df = 300.0\nlambda_f = 40.0\n"
                 "[pzc]\nk_dc = 4.0\nlambda_c = 2.0\n")
    m = tmp_path / "m.toml"
    m.write_text('duration = 5\n[trajectory]\nkind = "ellipse"\nf_r = 0.1\n'
                 "[gains.filter]\nk_df = 500.0\nlambda_f = 50.0\n"
                 "[gains.pzc]\nk_dc = 6.0\nlambda_c = 3.0\n")
    mission = missions.load(m)
    c = _gains(mission, 40.0)
    assert (c.filter.k_df, c.pzc.k_dc) == (500.0, 6.0) and "mission" in c.source
    c = _gains(mission, 40.0, gains_file=str(g))
    assert (c.filter.k_df, c.pzc.k_dc) == (300.0, 4.0)
    c = _gains(mission, 40.0, gains_file=str(g), lambda_f=77.0, k_dc=9.0)
    assert (c.filter.k_df, c.filter.lambda_f, c.pzc.k_dc, c.pzc.lambda_c) == (300.0, 77.0, 9.0, 2.0)
    assert c.source.startswith("flags over")
    # rate: flag > mission > gains file > 40
    assert requested_rate(paper, GainOptions()) == 40.0
    assert requested_rate(paper, GainOptions(gains_file=str(g))) == 25.0
    assert requested_rate(paper, GainOptions(gains_file=str(g), rate=100.0)) == 100.0
    with pytest.raises(UserError):
        requested_rate(paper, GainOptions(rate=5000.0))


def test_limit_precedence(tmp_path):
    paper = missions.paper_ellipse()
    assert choose_limits(paper, GainOptions()) == DEFAULT_LIMITS
    assert choose_limits(paper, GainOptions(max_speed=2.0)) == Limits(2.0, DEFAULT_LIMITS.max_yaw_rate)
    m = tmp_path / "m.toml"
    m.write_text('duration = 5\n[trajectory]\nkind = "circle"\nradius = 5.0\nspeed = 1.0\n'
                 "[limits]\nmax_speed = 2.0\nmax_yaw_rate = 1.0\n")
    mission = missions.load(m)
    assert choose_limits(mission, GainOptions()) == Limits(2.0, 1.0)
    assert choose_limits(mission, GainOptions(max_yaw_rate=0.5)) == Limits(2.0, 0.5)
