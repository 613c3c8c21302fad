"""The one policy for a flight's rate, gains and limits, for ``run``, ``demo``, ``simulate``,
``identify``, ``calibrate`` and ``tune`` alike (so ``simulate`` predicts what ``run`` flies).

Pure: it looks only at what it is given (the mission, the flags, what is known of the vehicle)
and reads no more than the ``--gains`` file named. First found wins:

* rate: ``--rate``; the mission's ``rate_hz``; the ``--gains`` file's ``rate_hz``;
  :data:`DEFAULT_RATE`. A live run then flies the rate the vehicle accepted.
* gains, the filter (k_df, lambda_f) and the PZC law separately: ``--k-df/--lambda-f/--k-dc/
  --lambda-c`` field by field over ``--gains FILE``; the mission's gains; the vehicle file's
  tuned gains; the shipped tuned gains for the rate, the vehicle's w_c and d_cen
  (:func:`companion.sim.gains.find_tuned`) — ``run`` without any of the above first looks for
  a bundled vehicle the live one matches (:func:`wants_preset`, :mod:`companion.live.presets`)
  and flies its gains as the vehicle's; the paper's gains (k_df 1000, lambda_f 120, k_dc 5,
  lambda_c 12).
* limits, speed and turn rate separately: ``--max-speed/--max-yaw-rate``; the lower of the
  mission's ``[limits]`` and the vehicle's own (its vehicle file, or the plant ``demo`` runs);
  :data:`~companion.core.limits.DEFAULT_LIMITS` (6 m/s, 6 rad/s).
* w_c and d_cen (to pick shipped gains): ``--w-c`` / ``--d-cen``; the mission's ``[vehicle]``;
  the vehicle's; the paper's w_c 20 rad/s and d_cen 0.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

from ..core import controllers
from ..core.filter import FilterGains
from ..core.limits import DEFAULT_LIMITS, Limits
from ..core.pzc import PZCGains
from ..errors import UserError
from ..sim import gains as gains_mod
from .config import DEFAULT_RATE, MAX_RATE

PAPER_W_C = 20.0       # rad/s: the actuator bandwidth we chose for the paper's plant


@dataclass(frozen=True)
class GainOptions:
    """What the flags ask for (``None``: not given)."""

    rate: float | None = None              # --rate
    gains_file: str | None = None          # --gains
    k_df: float | None = None              # --k-df ... --lambda-c: over the chosen gains
    lambda_f: float | None = None
    k_dc: float | None = None
    lambda_c: float | None = None
    max_speed: float | None = None         # --max-speed
    max_yaw_rate: float | None = None      # --max-yaw-rate
    w_c: float | None = None               # --w-c: the vehicle's, to pick shipped gains
    d_cen: float | None = None             # --d-cen
    controller_gains: Any = None           # --controller-gains: a baseline's own gains (its
                                           # gains dataclass, e.g. KanayamaGains; None: defaults)


@dataclass(frozen=True)
class KnownVehicle:
    """What is known of the vehicle beyond the flags: its vehicle file's tuned gains and
    limits (``companion run --vehicle``), or the plant ``demo`` starts."""

    gains: Any = None                      # companion.sim.gains.TunedGains, tuned for it
    limits: Limits | None = None           # what it can do
    w_c: float | None = None
    d_cen: float | None = None


@dataclass
class Choice:
    filter: FilterGains
    pzc: PZCGains
    source: str
    tuned_rate: float | None = None
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Resolved:
    rate: float             # the rate to ask for (or fly, when given)
    limits: Limits
    gains: Choice


def resolve(mission: Any, options: GainOptions, vehicle: KnownVehicle = KnownVehicle(),
            rate: float | None = None) -> Resolved:
    """Rate, gains and limits for ``mission`` flown with ``options`` on ``vehicle``; ``rate``,
    if given, is the rate actually flown (the vehicle's accepted one), else the requested."""
    rate = requested_rate(mission, options) if rate is None else rate
    return Resolved(rate, choose_limits(mission, options, vehicle),
                    choose_gains(mission, options, vehicle, rate))


def check(mission: Any, options: GainOptions, vehicle: KnownVehicle = KnownVehicle(),
          controller: str = controllers.DEFAULT) -> float:
    """Before anything connects: a bad ``--controller``, ``--gains`` file, rate or limit is a
    user error now, not after the vehicle answered. The rate asked."""
    check_controller(controller, options)
    rate = requested_rate(mission, options)
    choose_limits(mission, options, vehicle)
    if options.gains_file is not None:
        gains_mod.load(options.gains_file)
    return rate


def requested_rate(mission: Any, options: GainOptions) -> float:
    rate = options.rate or mission.rate_hz
    if rate is None and options.gains_file is not None:
        file_rate = gains_mod.load(options.gains_file).rate_hz
        rate = file_rate if math.isfinite(file_rate) else None
    rate = rate or DEFAULT_RATE
    if not (math.isfinite(rate) and 0 < rate <= MAX_RATE):
        raise UserError(f"rate must be between 0 and {MAX_RATE:g} Hz, not {rate!r}")
    return rate


def vehicle_keys(mission: Any, options: GainOptions,
                 vehicle: KnownVehicle = KnownVehicle()) -> tuple[float, float]:
    """(w_c, d_cen) that pick the shipped tuned gains."""
    v = mission.vehicle
    w_c = next(x for x in (options.w_c, v.w_c if v is not None else None, vehicle.w_c,
                           PAPER_W_C) if x is not None)
    d_cen = next(x for x in (options.d_cen, v.d_cen if v is not None else None, vehicle.d_cen,
                             0.0) if x is not None)
    return float(w_c), float(d_cen)


def wants_preset(mission: Any, options: GainOptions, vehicle: KnownVehicle) -> bool:
    """Nothing says what the vehicle is or which gains to fly: no vehicle file (flag or the
    mission's), no ``--gains``, no mission gains. Then ``run`` looks for a bundled vehicle the
    live vehicle matches (:mod:`companion.live.presets`) and warns when there is none."""
    return (vehicle.gains is None and vehicle.limits is None and options.gains_file is None
            and mission.vehicle_file is None and mission.filter_gains is None
            and mission.pzc_gains is None)


def choose_gains(mission: Any, options: GainOptions, vehicle: KnownVehicle,
                 rate: float) -> Choice:
    m = mission
    file = gains_mod.load(options.gains_file) if options.gains_file else None
    w_c, d_cen = vehicle_keys(mission, options, vehicle)
    shipped = gains_mod.find_tuned(rate, w_c, d_cen) or gains_mod.find_tuned(rate, w_c)
    own = vehicle.gains
    filt, fsrc = ((file.filter, f"--gains {options.gains_file}") if file else
                  (m.filter_gains, f"mission {m.source}") if m.filter_gains else
                  (own.filter, f"vehicle {own.source}") if own else
                  (shipped.filter, f"shipped {shipped.source}") if shipped else
                  (FilterGains(), "paper"))
    pzc, psrc = ((file.pzc, f"--gains {options.gains_file}") if file else
                 (m.pzc_gains, f"mission {m.source}") if m.pzc_gains else
                 (own.pzc, f"vehicle {own.source}") if own else
                 (shipped.pzc, f"shipped {shipped.source}") if shipped else
                 (PZCGains(), "paper"))
    o = options
    if o.k_df is not None or o.lambda_f is not None:
        filt = replace(filt, **{k: v for k, v in (("k_df", o.k_df), ("lambda_f", o.lambda_f))
                                if v is not None})
        fsrc = f"flags over {fsrc}"
    if o.k_dc is not None or o.lambda_c is not None:
        pzc = replace(pzc, **{k: v for k, v in (("k_dc", o.k_dc), ("lambda_c", o.lambda_c))
                              if v is not None})
        psrc = f"flags over {psrc}"
    source = fsrc if fsrc == psrc else f"filter: {fsrc}; pzc: {psrc}"
    tuned_rate = own.rate_hz if own else (shipped.rate_hz if shipped else None)
    return Choice(filt, pzc, source, tuned_rate)


def choose_limits(mission: Any, options: GainOptions,
                  vehicle: KnownVehicle = KnownVehicle()) -> Limits:
    """``mission`` None: no mission (``companion tune``)."""
    mission_limits = mission.limits if mission is not None else None
    known = [lim for lim in (mission_limits, vehicle.limits) if lim is not None]
    base = (Limits(max_speed=min(lim.max_speed for lim in known),
                   max_yaw_rate=min(lim.max_yaw_rate for lim in known),
                   min_turn_radius=max(lim.min_turn_radius for lim in known))
            if known else DEFAULT_LIMITS)
    try:
        return Limits(max_speed=options.max_speed if options.max_speed is not None
                      else base.max_speed,
                      max_yaw_rate=(options.max_yaw_rate if options.max_yaw_rate is not None
                                    else base.max_yaw_rate),
                      min_turn_radius=base.min_turn_radius)
    except ValueError as exc:
        raise UserError(str(exc)) from None


def gains_dict(filt: FilterGains, pzc: PZCGains) -> dict[str, Any]:
    d: dict[str, Any] = {"k_df": float(filt.k_df), "lambda_f": float(filt.lambda_f)}
    for key, value in asdict(pzc).items():
        d[key] = value if value is None or isinstance(value, (bool, str)) else float(value)
    return d


def limits_dict(limits: Limits) -> dict[str, float | None]:
    """The limits for a JSON result (``None``: no limit)."""
    out = {"max_speed": _finite_or_none(limits.max_speed),
           "max_yaw_rate": _finite_or_none(limits.max_yaw_rate)}
    if limits.min_turn_radius:
        out["min_turn_radius"] = limits.min_turn_radius
    return out


def _finite_or_none(x: float) -> float | None:
    return x if math.isfinite(x) else None


def check_controller(controller: str, options: GainOptions) -> None:
    """A known controller, no PZC gains asked of one that flies its own, and no own gains
    asked of one that flies PZC gains or of another kind than its own (a user error)."""
    try:
        entry = controllers.get(controller)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    o = options
    given = [flag for flag, value in (("--gains", o.gains_file), ("--k-df", o.k_df),
                                      ("--lambda-f", o.lambda_f), ("--k-dc", o.k_dc),
                                      ("--lambda-c", o.lambda_c)) if value is not None]
    if given and not entry.uses_pzc_gains:
        raise UserError(f"{' and '.join(given)} set{'s' if len(given) == 1 else ''} the filter "
                        f"+ PZC gains; --controller {controller} flies its own gains "
                        "(--controller-gains)")
    own = o.controller_gains
    if own is not None and (entry.uses_pzc_gains
                            or type(own) is not type(entry.default_gains)):
        raise UserError(f"--controller-gains ({type(own).__name__}) are not the gains "
                        f"--controller {controller} flies")


def build_tracker(controller: str, choice: Choice, limits: Limits,
                  own_gains: Any = None) -> tuple[Any, dict[str, Any], str]:
    """(the tracker ``controller`` names, its gains for the result, where they came from), for
    ``run``, ``demo`` and ``simulate`` alike: the policy's ``choice`` for a controller that
    flies the filter + PZC gains; for one with gains of its own, ``own_gains``
    (``--controller-gains``, checked by :func:`check_controller`), else its defaults. The
    result names the gains actually flown, so a comparison shows which baseline it beat."""
    entry = controllers.get(controller)
    if not entry.uses_pzc_gains:
        source = "defaults" if own_gains is None else "--controller-gains"
        return (controllers.build(controller, limits, own_gains=own_gains),
                entry.gains_dict(own_gains), entry.describe(own_gains, source))
    return (controllers.build(controller, limits, filter_gains=choice.filter,
                              pzc_gains=choice.pzc),
            gains_dict(choice.filter, choice.pzc), choice.source)
