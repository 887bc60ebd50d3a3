"""Fault injection (slow, ``-m slow``): a small training killed with SIGKILL at 20 random moments
and resumed each time ends complete; one killed right after its saves that begin an episode
ends with the unkilled run's weights, bit for bit (``benchmarks/kill_resume.py``)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_kill_9_at_random_moments_and_at_saves(tmp_path):
    proc = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "kill_resume.py"), "--kills", "20", "--keep", str(tmp_path)],
        capture_output=True, text=True, timeout=3600,
    )
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert proc.returncode == 0 and result["ok"], result["problems"]
    assert result["kills"] >= 20 and result["log_rows"] == result["steps"]
    assert result["kills_at_saves"] >= 1 and result["weights_identical"]
