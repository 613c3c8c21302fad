"""The tracker protocol: what the live loop, batch simulation and ``companion simulate`` fly.

One object turns a pose sample and a reference sample into a command, once per control step:
the PZC tracker (:mod:`companion.core.pzc`), the baselines (:mod:`companion.core.pid`,
:mod:`companion.core.kanayama`) and the identification manoeuvre (:mod:`companion.ident.excite`)
all satisfy it, so any of them flies a real vehicle (:mod:`companion.live.runner`) exactly as
it flies the simulated one (:mod:`companion.sim.batch`). :mod:`companion.core.controllers`
builds them by name.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from .signals import Command, Estimate, Measurement, Reference


@runtime_checkable
class Tracker(Protocol):
    """The contract every tracker keeps.

    ``name``
        What it is called on the command line and in results (``pzc``, ``pid``, ...).

    ``step(t, meas, ref) -> Command``
        One control step. ``t`` is the sample's own time in **vehicle seconds** (the
        autopilot's ``time_boot_ms`` / 1000 live, simulated time in batch), strictly
        increasing between resets; a tracker takes its dt from successive ``t`` and never
        reads a clock. ``meas`` is the sample taken at ``t``, ``ref`` the reference at the same
        instant. The command is within the limits the tracker was built with (the live loop
        refuses to send one that is not).

    ``reset()``
        Forget everything learned from earlier samples (filter state, integrators, previous
        values kept for differences, ``estimate``): the next ``step`` behaves as the first one
        after construction. The live loop calls it whenever tracking (re)starts: on engaging,
        after a pause, and after a gap in the telemetry long enough that dt would mislead.

    ``estimate``
        The pose the law used at the last step (:class:`~companion.core.signals.Estimate`):
        the filtered pose for PZC, the measurement itself for a tracker without a filter
        (:func:`raw_estimate`); ``None`` before the first step and after ``reset()``. The live
        loop logs it beside the measurement (the flight log's filtered pose).

    ``finished`` (optional)
        True once a scripted tracker (the identification manoeuvre,
        :mod:`companion.ident.excite`) has nothing more to ask: the live loop then ends the
        mission as done before its length. A tracker without it follows the mission to its end.

    Scalars or arrays: a tracker built with ``n=None`` runs one vehicle on Python floats; built
    with ``n=k`` it runs k vehicles at once and every field of ``meas``, ``ref``, the command
    and ``estimate`` is a numpy array of shape (k,) (``t`` stays one float: the vehicles share
    the clock). Gains may then be arrays too, one value per vehicle.
    """

    name: str
    estimate: Estimate | None

    def reset(self) -> None: ...

    def step(self, t: float, meas: Measurement, ref: Reference) -> Command: ...


def raw_estimate(meas: Measurement) -> Estimate:
    """The measurement as an :class:`Estimate`: what a tracker without a filter flies on."""
    return Estimate(meas.x, meas.y, meas.yaw, meas.vx, meas.vy, meas.yaw_rate)
