"""What the learner shows the code that feeds it steps and calibrates its Q*_g.

:class:`LearnerHandle` is the public face of a :class:`~mpg_agents.learning.learner.Learner`
that its sources of steps (:mod:`mpg_agents.learning.learner_episodes`: one actor in this
process; :mod:`mpg_agents.learning.actor_feed`: parallel actors) and its Q*_g calibrations
(:mod:`mpg_agents.learning.stage_calibration`) work on. They take it as an argument and never
import the learner, which imports them.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Protocol

import gymnasium as gym
import numpy as np
import torch

from mpg_agents.acting.agent import MPGAgent
from mpg_agents.learning.exploration import Explorer
from mpg_agents.learning.run_state import Counters
from mpg_agents.learning.train_config import TrainConfig
from mpg_agents.learning.training_stages import TrainingStage


class LearnerHandle(Protocol):
    """A stage's learner as its sources of steps and its calibrations see it."""

    config: TrainConfig
    stage: TrainingStage
    steps: int  # the iteration budget (a caller may lower it to end the run early)
    counters: Counters
    env: gym.Env  # the learner's own env (its actor's with one actor)
    calibration_env: gym.Env | None  # the env of in-scene calibrations, made at the first one
    policy: MPGAgent
    explorer: Explorer
    rng: np.random.Generator
    device: torch.device
    out: Path
    log: Callable[[str], None]

    def epsilon(self) -> float:
        """The exploration rate at the current iteration."""
        ...

    def objects_now(self, iteration: int) -> int | None:
        """The curriculum's object count at ``iteration`` (``None``: the env's own)."""
        ...

    def skipped_scene(self, k: int, error: Exception) -> None:
        """Count and log episode ``k``, whose seed gave no valid scene."""
        ...

    def save_state(self) -> None:
        """Write the weights and the resumable state."""
        ...
