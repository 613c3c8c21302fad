"""The suite's own pytest marks (pytest is imported here, not by the rest of the test bed)."""

from __future__ import annotations

import os

import pytest

# A SITL test enters `make sitl-test` (and so CI) only after ten runs in a row on this machine
# with another SITL running beside it (docs/sitl-testing.md); until then it is a candidate,
# run with PZC_CANDIDATE_SITL=1.
CANDIDATE = pytest.mark.skipif(not os.environ.get("PZC_CANDIDATE_SITL"),
                               reason="candidate SITL test (not yet ten runs in a row beside "
                                      "another SITL): PZC_CANDIDATE_SITL=1 runs it")
