"""Sinks for the command line: mission progress on stderr (tqdm), and a trace for the plot;
and a percentage bar for long computations (tuning).

Both are cheap enough for a 1 kHz loop: the bar is redrawn at most ten times a wall second.
"""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager

from .live.events import LoopRecord, StatusEvent


@contextmanager
def progress_bar(label: str, enabled: bool = True):
    """``with progress_bar(label) as progress:``: a tqdm bar on stderr moved by
    ``progress(fraction)``, closed on the way out; ``progress`` is None when disabled."""
    if not enabled:
        yield None
        return
    from tqdm import tqdm
    bar = tqdm(total=100, desc=label, file=sys.stderr, mininterval=0.5,
               bar_format="{desc} {percentage:3.0f}%|{bar}| {elapsed}<{remaining}")

    def progress(frac: float) -> None:
        if 100 * frac > bar.n:
            bar.update(round(100 * frac - bar.n, 1))
    try:
        yield progress
    finally:
        bar.close()


class ProgressSink:
    def __init__(self, duration: float, label: str = "mission"):
        self.duration = duration
        self.label = label
        self._bar = None                 # created when tracking starts, after the set-up logs
        self._next = 0.0
        self._step = max(duration / 500.0, 0.02)   # mission seconds between looks at the clock
        self._next_draw = 0.0

    def _open(self):
        from tqdm import tqdm
        self._bar = tqdm(total=round(self.duration, 1), desc=self.label, file=sys.stderr,
                         bar_format="{desc} {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s"
                                    "{postfix}")
        return self._bar

    def record(self, rec: LoopRecord) -> None:
        if rec.mission_time < self._next:
            return
        self._next = rec.mission_time + self._step
        now = time.monotonic()
        if now < self._next_draw:
            return
        self._next_draw = now + 0.1
        bar = self._bar or self._open()
        bar.n = round(min(rec.mission_time, self.duration), 1)
        bar.set_postfix_str(f"error {rec.err_pos:.2f} m", refresh=False)
        bar.refresh()

    def status(self, event: StatusEvent) -> None:
        bar = self._bar
        if event.kind in ("failsafe", "paused", "resumed", "pilot_override"):
            if bar is not None:
                bar.write(f"{event.kind}: {event.reason}", file=sys.stderr)
        elif event.kind == "mission_done" and bar is not None:
            bar.n = bar.total
            bar.refresh()

    def close(self) -> None:
        if self._bar is not None:
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
