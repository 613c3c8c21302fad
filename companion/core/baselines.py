"""The baseline trackers compared with PZC, under their old name: the PID of the paper's
Section 5 (:mod:`companion.core.pid`) and Kanayama et al.'s law (:mod:`companion.core.kanayama`).
"""

from .kanayama import KanayamaGains, KanayamaTracker
from .pid import PIDGains, PIDTracker

__all__ = ["KanayamaGains", "KanayamaTracker", "PIDGains", "PIDTracker"]
