"""Robust tuning: gains that hold on an identified vehicle and on its plausible neighbours.

:mod:`companion.sim.tuning` finds the best gains for one linear model; on a real autopilot (rate
limits, delay, coupling) gains that exploit that model's exact form meet the limits as a relay
and limit-cycle. Here every candidate gain set is simulated, in one batch, on

* an **ensemble**: the identified vehicle (:mod:`companion.sim.vehicle_file`) and neighbours with
  each identified parameter perturbed (lags and rate limits by tens of percent, delays by one or
  two telemetry samples, the skid-steer coupling), deterministic for a seed;
* the **telemetry as the autopilot delivers it**: samples on the scheduler's ticks (ArduPilot's
  20 / 20 / 20 / 40 ms at 40 Hz) with EKF-like noise;
* **references**: the missions given, else the paper's ellipse at 0.04, 0.08 and 0.12 Hz plus a
  slower one (0.02 Hz), so gains that suit a fast reference cannot orbit a slow one.

The objective rewards steady tracking on every reference (log of the ensemble-mean steady RMS,
so a 5 cm and a 50 cm reference count alike, plus a smaller share of f_cost for the approach)
and penalises command chatter (total variation of the setpoints per second). A candidate whose
**worst** neighbour limit-cycles (yaw-rate setpoint at its limit more than 5 % of the second
half) or diverges on any reference is rejected outright.

The search is :mod:`companion.sim.tuning`'s (seeded random search, then rounds of perturbation
around the elite) over the same gain space, with the actuator lead left out: a lead's gain is
what turns a rate limit into a relay. On top of it, this search chooses the law's extensions for
rate-limited, delayed inner loops (:mod:`companion.core.pzc`): a separate preview time for the
turning part of the acceleration feed-forward (``accel_ff_turn``) and braking-curve P terms with
integrator hold (``brake_accel``, ``brake_yaw_accel``), each behind a flag, the braking
accelerations as factors of the identified vehicle's decelerations (:data:`EXTRA_RANGES`), and
on a late speed loop (``predict_min_delay``, the autopilot profile's) the speed's delay
prediction (``predict_s``, a share of the identified delay: :data:`PREDICT_RANGE`); on a speed
loop identified to overshoot (``cancel_min_overshoot``, the profile's) every candidate sends
its speed through that overshoot's inverse (:meth:`RobustConfig.overshoot_cancel`). The
seeds include the speed channel's delay + lag as the speed preview, so the search starts where
the physics says the preview belongs.

The modules, in the order a tune runs through them: :mod:`.config` (what to tune for:
:class:`RobustConfig`, :class:`Spread`), :mod:`.references` (the paper's ellipses and their
peaks), :mod:`.ensemble` (the vehicle and its neighbours), :mod:`.candidates` (the search space:
seeds, draws, perturbations, a candidate as gains and as a tracker), :mod:`.evaluation` (every
candidate on every vehicle and reference, the objective and the rejections), :mod:`.pool` (the
worker processes) and :mod:`.search` (:func:`~.search.tune`: the rounds and the confirmed winner).
Each name is imported from the module that defines it; this one imports none of them, so a
caller that needs only the configuration does not load the simulations.

May import: ``core`` and the ``sim`` modules beneath it (plant, plant_lanes, batch, tuning,
gains); imported by ``sim.vehicle_gains`` and the commands that tune.
"""
