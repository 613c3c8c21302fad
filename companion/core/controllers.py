"""The controllers by name: what ``--controller`` chooses, for ``simulate``, ``run`` and ``demo``.

    build(name, limits, *, filter_gains=None, pzc_gains=None, n=None) -> Tracker

builds a :class:`~companion.core.tracker.Tracker` for one vehicle (``n=None``) or ``n`` at once.
``pzc`` flies the filter and PZC gains it is given (the callers' gains policy picks them; ``None``
is the paper's); a controller with gains of its own (``pid``, ``kanayama``) flies its defaults
and takes no filter or PZC gains.

Adding a controller: a module in ``companion/core`` with its tracker (the protocol in
:mod:`companion.core.tracker`), ``DEFAULT_GAINS`` (its gains dataclass, or ``None`` if it flies
the filter + PZC gains) and ``build(limits, n)`` (``build(limits, n, filter_gains, pzc_gains)``
for one that flies the filter + PZC gains), and one ``_register(...)`` line below; ``--controller``
offers it everywhere from then on. The modules are imported on first use, not here: building
the command line (``companion --help``) needs the names only, and the trackers pull in numpy.
"""

from __future__ import annotations

import importlib
from dataclasses import asdict, dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any

from .limits import Limits
from .tracker import Tracker

if TYPE_CHECKING:
    from .filter import FilterGains
    from .pzc import PZCGains

DEFAULT = "pzc"


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

    def gains_dict(self) -> dict[str, Any]:
        """Its own default gains as plain numbers and strings (for a JSON result)."""
        gains = self.default_gains
        if gains is None:
            return {}
        return {k: v if isinstance(v, (bool, str)) else float(v) for k, v in asdict(gains).items()}

    def defaults_source(self) -> str:
        """Where its gains come from, for ``gains_source``: "pid defaults (...): kp 3.5, ..."."""
        listed = ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}"
                           for k, v in self.gains_dict().items())
        return f"{self.name} defaults ({self.about}): {listed}"


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
          pzc_gains: PZCGains | None = None, n: int | None = None) -> Tracker:
    """The tracker of controller ``name`` within ``limits``, for one vehicle or ``n``.

    ``filter_gains`` / ``pzc_gains`` are for a controller that flies them (``pzc``; ``None``:
    the paper's); giving them to one with gains of its own is a ValueError, not a silent no-op.
    """
    controller = get(name)
    if controller.uses_pzc_gains:
        return controller.code().build(limits, n, filter_gains, pzc_gains)
    if filter_gains is not None or pzc_gains is not None:
        raise ValueError(f"controller {name!r} flies its own gains, not filter / PZC gains")
    return controller.code().build(limits, n)
