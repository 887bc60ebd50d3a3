"""StopFlag: inside its block SIGINT and SIGTERM only ask the loop to stop; the previous handlers
come back when the block ends."""

from __future__ import annotations

import os
import signal

import pytest

from mpg_agents.learning.stop_signal import StopFlag


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_stop_signal_sets_the_flag_and_the_handlers_come_back(signum):
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    with StopFlag() as stop:
        assert not stop.asked
        os.kill(os.getpid(), signum)  # the process goes on: the handler only sets the flag
        assert stop.asked
    assert {s: signal.getsignal(s) for s in before} == before
