"""The controllers by name: what ``--controller`` chooses, for ``simulate``, ``run`` and ``demo``.

    build(name, limits, *, filter_gains=None, pzc_gains=None, own_gains=None, n=None) -> Tracker

builds a :class:`~companion.core.tracker.Tracker` for one vehicle (``n=None``) or ``n`` at once.
``pzc`` flies the filter and PZC gains it is given (the callers' gains policy picks them; ``None``
is the paper's); a controller with gains of its own (``pid``, ``kanayama``) flies the instance of
its gains dataclass it is given (``own_gains``; ``None``: its defaults) and takes no filter or PZC
gains. :meth:`Controller.with_gains` makes that instance from a few fields over the defaults
(``--controller-gains``) and checks them here, beside the gains they set: a classical baseline is
only a fair one with gains picked for the vehicle, not with defaults that limit-cycle on it.

Adding a controller: a module in ``companion/core`` with its tracker (the protocol in
:mod:`companion.core.tracker`), ``DEFAULT_GAINS`` (its gains dataclass, or ``None`` if it flies
the filter + PZC gains) and ``build(limits, n, gains=None)`` (``build(limits, n, filter_gains,
pzc_gains)`` for one that flies the filter + PZC gains), and one ``_register(...)`` line below;
``--controller`` and ``--controller-gains`` offer it everywhere from then on. A numeric gain
must be > 0 unless its field's metadata says ``{MAY_BE_ZERO: True}`` (then >= 0; pid's
k_I and k_D). The modules are imported on first use, not here: building
the command line (``companion --help``) needs the names only, and the trackers pull in numpy.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields, replace
from types import ModuleType
from typing import TYPE_CHECKING, Any

from .limits import Limits
from .tracker import Tracker

if TYPE_CHECKING:
    from .filter import FilterGains
    from .pzc import PZCGains

DEFAULT = "pzc"
MAY_BE_ZERO = "may_be_zero"   # a gains field's metadata key: 0 is a meaningful value (PID's k_I)


@dataclass(frozen=True)
class Controller:
    """One registered controller: its ``name``, the ``module`` of ``companion.core`` that holds
    it, a few words ``about`` it, and whether it flies the filter + PZC gains of the callers'
    gains policy (``uses_pzc_gains``) or gains of its own (the module's ``DEFAULT_GAINS``)."""

    name: str
    module: str
    about: str
    uses_pzc_gains: bool = False

    def code(self) -> ModuleType:
        return importlib.import_module(f"{__package__}.{self.module}")

    @property
    def default_gains(self) -> Any:
        """The gains dataclass it flies by default (``None`` for one that flies PZC gains)."""
        return self.code().DEFAULT_GAINS

    def gain_defaults(self) -> dict[str, Any]:
        """Its own gains' fields and their defaults, in order ({} for one that flies PZC gains):
        what ``--controller-gains`` may set, and (a str default) which fields are words."""
        gains = self.default_gains
        return {} if gains is None else {f.name: getattr(gains, f.name) for f in fields(gains)}

    def with_gains(self, values: Mapping[str, float | str]) -> Any:
        """Its default gains with ``values`` over them, field by field (the rest stay default).

        ValueError, naming the field, for a controller without gains of its own, an unknown
        field, a word for a number (or a number for a word), or a number that is not finite or
        not > 0 (>= 0 where the field's metadata says :data:`MAY_BE_ZERO`): Kanayama's proof
        of stability needs K_x, K_y, K_th > 0, and a PID without k_P is not one.
        """
        gains = self.default_gains
        if gains is None:
            raise ValueError(f"{self.name} flies the filter + PZC gains, none of its own")
        known = {f.name: f for f in fields(gains)}
        for key, value in values.items():
            f = known.get(key)
            if f is None:
                raise ValueError(f"{self.name} has no gain {key!r} (its gains: "
                                 f"{', '.join(known)})")
            if isinstance(getattr(gains, key), str):
                if not isinstance(value, str):
                    raise ValueError(f"{key} is a word, not a number: {value!r}")
                continue                      # the dataclass checks its words (__post_init__)
            if isinstance(value, (str, bool)):
                raise ValueError(f"{key} must be a number, not {value!r}")
            zero_ok = bool(f.metadata.get(MAY_BE_ZERO))
            if not (math.isfinite(value) and (value >= 0 if zero_ok else value > 0)):
                raise ValueError(f"{key} must be a finite number {'>= 0' if zero_ok else '> 0'}, "
                                 f"not {value:g}")
        return replace(gains, **values)

    def gains_dict(self, gains: Any = None) -> dict[str, Any]:
        """``gains`` (``None``: its own defaults) as plain numbers and strings (for a JSON
        result)."""
        gains = self.default_gains if gains is None else gains
        if gains is None:
            return {}
        return {k: v if isinstance(v, (bool, str)) else float(v) for k, v in asdict(gains).items()}

    def describe(self, gains: Any = None, source: str = "defaults") -> str:
        """Where its gains come from and what they are, for ``gains_source``: "pid defaults
        (...): kp 3.5, ..."; ``source`` names where ``gains`` came from (a flag, say)."""
        listed = ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}"
                           for k, v in self.gains_dict(gains).items())
        return f"{self.name} {source} ({self.about}): {listed}"

    def defaults_source(self) -> str:
        """Its default gains, for ``gains_source``: "pid defaults (...): kp 3.5, ..."."""
        return self.describe()


REGISTRY: dict[str, Controller] = {}


def _register(controller: Controller) -> None:
    REGISTRY[controller.name] = controller


_register(Controller("pzc", "pzc", "the model-free filter and PZC law of Lee et al. (2024)",
                     uses_pzc_gains=True))
_register(Controller("pid", "pid", "the paper's Section 5 PID baseline"))
_register(Controller("kanayama", "kanayama", "Kanayama et al. (1990), gains chosen by hand"))

NAMES: tuple[str, ...] = tuple(REGISTRY)


def get(name: str) -> Controller:
    """The controller called ``name``; ValueError naming the choices otherwise."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown controller {name!r}; choose one of {', '.join(NAMES)}") from None


def build(name: str, limits: Limits = Limits(), *, filter_gains: FilterGains | None = None,
          pzc_gains: PZCGains | None = None, own_gains: Any = None,
          n: int | None = None) -> Tracker:
    """The tracker of controller ``name`` within ``limits``, for one vehicle or ``n``.

    ``filter_gains`` / ``pzc_gains`` are for a controller that flies them (``pzc``; ``None``:
    the paper's); ``own_gains`` (an instance of its gains dataclass, ``None``: its defaults) for
    one with gains of its own. Either given to the other kind is a ValueError, not a silent
    no-op: a comparison that quietly flew defaults would measure the wrong law.
    """
    controller = get(name)
    if controller.uses_pzc_gains:
        if own_gains is not None:
            raise ValueError(f"controller {name!r} flies filter / PZC gains, none of its own")
        return controller.code().build(limits, n, filter_gains, pzc_gains)
    if filter_gains is not None or pzc_gains is not None:
        raise ValueError(f"controller {name!r} flies its own gains, not filter / PZC gains")
    if own_gains is not None and type(own_gains) is not type(controller.default_gains):
        raise ValueError(f"controller {name!r} flies {type(controller.default_gains).__name__}, "
                         f"not {type(own_gains).__name__}")
    return controller.code().build(limits, n, own_gains)
