"""A field run's coverage for its result: the positions the rover took, scored against the
field's swaths at the end (:mod:`companion.mission.coverage`): the ``coverage`` object of
``companion run --json``. A :class:`~companion.live.events.Sink`; it keeps a position every
``STEP`` metres of travel, so an hour's field costs little memory and scoring stays quick."""

from __future__ import annotations

import math
from typing import Any

from ..mission.coverage import FieldCover, figures
from .events import LoopRecord, StatusEvent

STEP = 0.02      # m of travel between kept positions


class CoverageSink:
    """Positions of the tracked cycles (the estimate the loop tracked), and the frame the
    mission was anchored in: the pose of the first tracked cycle for a "start"-frame mission,
    as the runner anchors it (``Mission.anchored``)."""

    def __init__(self, cover: FieldCover, frame: str):
        self.cover, self.frame = cover, frame
        self.points: list[tuple[float, float]] = []
        self.placed: FieldCover | None = None

    def record(self, rec: LoopRecord) -> None:
        if self.placed is None:
            self.placed = (self.cover.placed(rec.x, rec.y, rec.yaw) if self.frame == "start"
                           else self.cover)
        if not self.points or math.dist(self.points[-1], (rec.x, rec.y)) >= STEP:
            self.points.append((rec.x, rec.y))

    def status(self, event: StatusEvent) -> None:
        pass

    def close(self) -> None:
        pass

    def figures(self) -> dict[str, Any] | None:
        """The coverage figures, or None before any tracked cycle."""
        if self.placed is None:
            return None
        return figures(self.points, self.placed)
