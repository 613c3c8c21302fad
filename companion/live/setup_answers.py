"""The control channel answered while a session sets up, before the loop polls it.

Connecting, the EKF origin, the telemetry rate, the parameters a bundled vehicle is recognised
by: a session's setup takes seconds (more on a loaded board), and a ground station or
``companion control ... status`` asking meanwhile would get no answer and conclude the rover is
gone. :class:`SetupAnswers` polls the :class:`companion.live.events.ControlChannel` in a thread
for exactly that span and hands it to the loop after (one consumer at a time):

- ``status``: what ``status()`` gives (the session's: ``runner.core.status_fields`` with
  ``"state": "setting_up"``, the loop's keys) and ``"step"``, what the setup is doing;
- ``abort``: the session ends before anything is asked of the vehicle (``on_abort``);
- every other verb is refused, naming the step: the loop takes them once it runs.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from typing import Any

from .events import ControlChannel, ControlRequest

SETTING_UP = "setting_up"   # the status's state during the setup (the loop's: loop_state.State)
POLL_EVERY = 0.05           # wall s between two polls (a request waits at most this long)


class SetupAnswers:
    """``with SetupAnswers(control, status, on_abort) as answers: answers.step = "..."``.

    ``status()`` gives the status fields the setup knows (called from the answering thread:
    it must only read); ``on_abort()`` asks the setup to stop (it must be safe from a thread).
    Without a control channel it does nothing."""

    def __init__(self, control: ControlChannel | None, status: Callable[[], dict[str, Any]],
                 on_abort: Callable[[], None]):
        self.control = control
        self.step = "starting"
        self._status, self._on_abort = status, on_abort
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="setup-answers", daemon=True)

    def __enter__(self) -> SetupAnswers:
        if self.control is not None:
            self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.control is not None:
            self._done.set()
            self._thread.join()

    def _run(self) -> None:
        assert self.control is not None
        while not self._done.wait(POLL_EVERY):
            for request in self.control.poll():
                self.answer(request)

    def answer(self, request: ControlRequest) -> None:
        verb, step = request.verb, self.step
        if verb == "status":
            request.reply(True, json.dumps({**self._status(), "step": step}))
        elif verb == "abort":
            self._on_abort()
            request.reply(True, f"stopping the setup ({step}): nothing is asked of the vehicle")
        else:
            request.reply(False, f"still setting up ({step}): `{verb}` once the loop runs")
