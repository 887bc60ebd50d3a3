"""Which env seed each episode of a training run resets with.

A run with seed ``s`` resets its ``k``-th training episode with ``s * 1_000_003 + k`` and its
``i``-th demonstration episode with ``s * 1_000_003 + 800_000 + i`` and its ``j``-th Q*_g
calibration episode with ``s * 1_000_003 + 900_000 + j``. The prime stride keeps the runs of
nearby seeds apart; the offsets keep demonstrations and calibrations clear of the run's
training episodes and, for seed 0, of the Table I held-out seeds (500000-) and the tuning
seeds (700000-) that evaluations use.
"""

from __future__ import annotations

RUN_SEED_STRIDE = 1_000_003
"""Env seeds of one run lie in ``[s * RUN_SEED_STRIDE, (s + 1) * RUN_SEED_STRIDE)``."""

DEMONSTRATION_SEED_OFFSET = 800_000
"""Where a run's demonstration episodes start inside its seed range."""

CALIBRATION_SEED_OFFSET = 900_000
"""Where a run's Q*_g calibration episodes start inside its seed range."""


def episode_seed(run_seed: int, k: int, demonstration: bool = False, calibration: bool = False) -> int:
    """The env seed of episode ``k`` (>= 0) of the run seeded ``run_seed``: a training
    episode, with ``demonstration`` an oracle demonstration episode, with ``calibration`` a
    Q*_g calibration episode."""
    if k < 0:
        raise ValueError(f"episode index must be >= 0, got {k}")
    if demonstration and calibration:
        raise ValueError("an episode is a demonstration or a calibration, not both")
    offset = DEMONSTRATION_SEED_OFFSET if demonstration else CALIBRATION_SEED_OFFSET if calibration else 0
    return run_seed * RUN_SEED_STRIDE + offset + k
