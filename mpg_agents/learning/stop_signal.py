"""Stopping a training loop from outside: SIGINT or SIGTERM asks it to stop after the step it is
taking, saving that step first (a run in the background, where SIGINT is ignored, is stopped with
SIGTERM). Both the reinforcement-learning loop (:class:`~mpg_agents.learning.learner.Learner`) and
behaviour cloning (:func:`~mpg_agents.imitation.bc_training.train_bc`) stop this way.
"""

from __future__ import annotations

import signal
import threading
from typing import Any

STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM)


class StopRequested(Exception):
    """Raised inside the loop when SIGINT/SIGTERM arrived; the state is saved first."""


class StopFlag:
    """``with StopFlag() as stop:`` the stop signals set ``stop.asked`` instead of ending the
    process; the loop saves and raises :class:`StopRequested` when it sees it. The handlers are
    installed in the main thread only (Python delivers signals there) and the previous ones put
    back on leaving the block."""

    def __init__(self) -> None:
        self.asked = False
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> StopFlag:
        if threading.current_thread() is threading.main_thread():
            self._previous = {s: signal.signal(s, self._ask) for s in STOP_SIGNALS}
        return self

    def __exit__(self, *exc: object) -> None:
        for s, handler in self._previous.items():
            signal.signal(s, handler)
        self._previous = {}

    def _ask(self, signum: int, frame: Any) -> None:
        self.asked = True
