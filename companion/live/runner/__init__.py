"""The live control loop, one role a module: state (core), ending, engaging, failsafes, requests, the loop.
May import: what ``companion.live`` may (``core``, ``mission``, ``errors``) and its sibling modules (link, telemetry, health, loop_state, stats, events, config, handover).
"""

from ..config import RunnerConfig
from .core import stop_cause
from .loop import Runner

__all__ = ["Runner", "RunnerConfig", "stop_cause"]
