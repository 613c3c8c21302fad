"""A Sink that shows mission progress on stderr (tqdm), cheap enough for a 1 kHz loop."""

from __future__ import annotations

import sys

from .events import LoopRecord, StatusEvent


class ProgressSink:
    def __init__(self, duration: float, label: str = "mission"):
        from tqdm import tqdm
        self.duration = duration
        self._bar = tqdm(total=round(duration, 1), unit="s", desc=label, file=sys.stderr,
                         leave=True, bar_format="{desc} {percentage:3.0f}%|{bar}| "
                                                "{n:.1f}/{total:.1f} s {postfix}")
        self._next = 0.0
        self._step = max(duration / 200.0, 0.05)   # mission seconds between bar updates

    def record(self, rec: LoopRecord) -> None:
        if rec.mission_time < self._next:
            return
        self._next = rec.mission_time + self._step
        self._bar.n = round(min(rec.mission_time, self.duration), 1)
        self._bar.set_postfix_str(f"error {rec.err_pos:.2f} m", refresh=False)
        self._bar.refresh()

    def status(self, event: StatusEvent) -> None:
        if event.kind in ("failsafe", "paused", "resumed", "pilot_override"):
            self._bar.write(f"{event.kind}: {event.reason}", file=sys.stderr)
        if event.kind == "mission_done":
            self._bar.n = self._bar.total
            self._bar.refresh()

    def close(self) -> None:
        self._bar.close()


class TraceSink:
    """Keeps the path and the reference (for a plot): t, x, y, x_ref, y_ref per cycle."""

    def __init__(self) -> None:
        self.log: dict[str, list[float]] = {k: [] for k in ("t", "x", "y", "x_ref", "y_ref")}

    def record(self, rec: LoopRecord) -> None:
        log = self.log
        log["t"].append(rec.mission_time)
        log["x"].append(rec.x)
        log["y"].append(rec.y)
        log["x_ref"].append(rec.x_ref)
        log["y_ref"].append(rec.y_ref)

    def status(self, event: StatusEvent) -> None:
        pass

    def close(self) -> None:
        pass
