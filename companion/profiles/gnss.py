"""The receiver's quality and what the companion does about it: a policy per GNSS class.

The autopilot reports its receiver in GPS_RAW_INT (id 24): ``fix_type`` (GPS_FIX_TYPE) and,
in MAVLink 2, ``h_acc`` (the accuracy the receiver claims, mm; 0 when unknown). ArduPilot and
PX4 both send it; ArduPilot's EKF takes any GNSS position as at least 0.5 m uncertain whatever
the receiver claims (EK3_POSNE_M_NSE), so a receiver that falls from RTK fixed to float, or
multipath that moves a "fixed" solution, passes into LOCAL_POSITION_NED without a flag
(docs/gnss.md). The companion judges the class itself:

* **The run's class** is the one the receiver had when the companion engaged: a run that began
  at RTK fixed was promised centimetres, one that began with plain GPS a metre. The accuracy to
  expect is said then, before the rover moves (:func:`expectation`).
* **A drop below it** (:func:`action`): from RTK fixed to anything less, ``hold``: the rover
  stops on the path with the reference's clock held, and once the run's class has been back for
  ``back_for`` s and the estimate shows the rover at rest (``rest_speed``: the estimator has
  re-converged) it rejoins the path where it stopped, skipping nothing (ArduPilot #8787: "only
  RTK FIX can be trusted"; float's decimetres are ten times the centimetres the run promised).
  From a lesser class to a lesser one still (DGPS to a 3D fix), ``slow``: the reference runs at
  ``slow_factor`` of its speed, so the metre the receiver may now be off is crossed slowly, until
  the class is back. No fix at all: ``hold`` whatever the run began with.
* **The same class or better**: ``continue``.

A policy is data: an autopilot that judges its receiver differently gets its own
:class:`GnssPolicy` in its profile. Pure: no I/O, no clock.
"""

from __future__ import annotations

from dataclasses import dataclass

GPS_RAW_INT_ID = 24
GPS2_RAW_ID = 124

CONTINUE, SLOW, HOLD = "continue", "slow", "hold"

# GPS_FIX_TYPE (common.xml) -> (rank, name): a higher rank is a better class
_CLASSES = {
    0: (0, "no GPS"), 1: (0, "no fix"), 2: (1, "2D fix"), 3: (2, "3D fix"),
    4: (3, "DGPS"), 7: (2, "static"), 8: (3, "PPP"), 5: (4, "RTK float"), 6: (5, "RTK fixed"),
}
RTK_FIXED_RANK = 5
USABLE_RANK = 2           # a 3D fix: anything below steers by nothing the receiver knows


def rank(fix_type: int) -> int:
    """The class's rank (0: no fix ... 5: RTK fixed); an unknown fix type counts as no fix."""
    return _CLASSES.get(int(fix_type), (0, ""))[0]


def name(fix_type: int) -> str:
    """The class's name for people ("RTK fixed", "3D fix", ...)."""
    return _CLASSES.get(int(fix_type), (0, f"fix type {int(fix_type)}"))[1]


@dataclass(frozen=True)
class GnssPolicy:
    """What a drop in the receiver's class does (see the module docstring)."""

    from_rtk_fixed: str = HOLD       # any drop from RTK fixed
    otherwise: str = SLOW            # a drop from a lesser class, still a 3D fix or better
    no_fix: str = HOLD               # below a 3D fix
    slow_factor: float = 0.5         # the reference's speed while slowed
    back_for: float = 1.5            # s the run's class must be back before resuming
    # m/s: and the companion steers by the receiver until the estimate agrees with it again
    # (companion.live.gnss_jump), or, knowing no relation to the receiver yet, the estimate
    # must show the held rover at rest (ArduPilot's EKF, re-converging after float, moves its
    # position and velocity for seconds: measured in docs/gnss.md)
    rest_speed: float = 0.05
    # a fix stepping this far (m) beyond the rover's own motion is a jump, ridden through on
    # that motion for at most jump_max_ride s (companion.live.gnss_jump), then held
    jump_threshold: float = 0.15
    jump_max_ride: float = 10.0
    rate_hz: float = 10.0            # GPS_RAW_INT asked for at this rate
    stale_after: float = 2.0         # s without GPS_RAW_INT: the class is unknown (continue)


def action(policy: GnssPolicy, start_fix: int, fix: int) -> str:
    """``continue``, ``slow`` or ``hold`` for a receiver at ``fix`` in a run begun at
    ``start_fix`` (GPS_FIX_TYPE values)."""
    now, start = rank(fix), rank(start_fix)
    if start < USABLE_RANK:
        return CONTINUE       # a run begun without a fix does not steer by the receiver
    if now < USABLE_RANK:
        return policy.no_fix
    if now >= start:
        return CONTINUE
    return policy.from_rtk_fixed if start >= RTK_FIXED_RANK else policy.otherwise


def expectation(fix: int, h_acc: float | None) -> str:
    """What to expect of a run begun at ``fix`` with the receiver claiming ``h_acc`` m (None:
    it claims nothing): said before the rover moves."""
    claim = (f"the receiver claims {h_acc:.2f} m" if h_acc is not None
             else "the receiver claims no accuracy")
    if rank(fix) >= RTK_FIXED_RANK:
        return (f"GNSS {name(fix)} ({claim}): the rover's true path within centimetres of "
                "the estimate's; a drop from RTK fixed holds the rover until it is back")
    return (f"GNSS {name(fix)} ({claim}): the estimate, and so the rover's true path, may be "
            f"off by about {h_acc if h_acc is not None else 1.0:.1f} m; the companion adds "
            "centimetres to that, and cannot remove it")
