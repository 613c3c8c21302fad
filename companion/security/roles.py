"""The four roles a fleet member's certificate may carry, and what each is for.

Kept apart from :mod:`.pki` so the command line can list them without loading the
cryptography library (``companion --help`` stays instant).
"""

from __future__ import annotations

ROVER, OPERATOR, MONITOR, ROUTER = "rover", "operator", "monitor", "router"
ROLES = (ROVER, OPERATOR, MONITOR, ROUTER)
POSSESSIVE = {ROVER: "a rover's", OPERATOR: "an operator's", MONITOR: "a monitor's",
              ROUTER: "a router's"}
