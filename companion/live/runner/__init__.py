"""The live control loop, one role a module: state (core), ending, engaging, failsafes, requests, the loop.
May import: ``core``, ``errors``, ``mission`` (load-mission) and the ``live`` modules beneath the loop (link, telemetry, health, loop_state, stats, events, config, handover); never ``session``.
"""

from ..config import RunnerConfig
from .core import stop_cause
from .loop import Runner

__all__ = ["Runner", "RunnerConfig", "stop_cause"]
