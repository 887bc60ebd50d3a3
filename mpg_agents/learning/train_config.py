"""The algorithm's settings of a training run (``mpg-train``'s ``--config`` top level).

One :class:`TrainConfig` drives the learner (:mod:`mpg_agents.learning.learner`), and the SB3 adapter
(:mod:`mpg_agents.sb3`) takes its defaults from it, so both train with the same settings.
What a stage trains (env, branches, curriculum, alternation, ...) is its
:class:`~mpg_agents.learning.training_stages.TrainingStage`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

from mpg_agents.acting.grasp_threshold import UNCALIBRATED
from mpg_agents.learning.td_step import TDStepConfig
from mpg_agents.learning.training_stages import check_fields


@dataclass
class TrainConfig:
    """The algorithm's settings for a stage; defaults are the paper's where it gives them."""

    steps: int | None = None  # training iterations (one env step + one gradient step); None: the stage's
    seed: int = 0
    variant: str = "small"
    num_objects: int | None = None  # a fixed object count; None: the stage's curriculum or the env's count
    # Paper, Training Details.
    gamma: float = 0.5
    learning_rate: float = 1e-4
    weight_decay: float = 2**-5
    betas: tuple[float, float] = (0.9, 0.99)
    epsilon_start: float = 0.5
    epsilon_end: float = 0.1
    epsilon_decay_steps: int | None = None  # None: over the whole run
    # Replay and updates.
    batch_size: int = 2
    replay_capacity: int = 5000
    priority_alpha: float = 1.0
    target_update_every: int = 100
    grasp_symmetry: bool = True
    max_grad_norm: float | None = None  # the paper clips nothing (see td_step.TDStepConfig)
    q_bounds: tuple[float, float] | None = None  # clamp TD targets to the feasible returns (see td_step.TDStepConfig)
    # Training aids (paper, Simulation Experiments).
    heuristic_after_failed_grasps: int = 2
    # The run's starting Q*_g, overriding the starting checkpoint's; None: the checkpoint's
    # (mpg_agents.acting.grasp_threshold.starting_q_star).
    q_star: float | None = UNCALIBRATED
    # Not the paper's (pure RL): oracle episodes whose transitions seed the replay of a fresh run (0: none).
    demonstration_episodes: int = 0
    # The discriminator: the fixed Stage II grasp net that scores states for the move/push rewards.
    discriminator: str | None = None
    # Bookkeeping.
    checkpoint_every: int = 100
    window: int = 200  # grasp success rate per this many iterations (paper)
    torch_threads: int = 2
    device: str = "auto"  # networks and batches: auto (CUDA when available) | cpu | cuda; replay and envs stay on the host
    net_config: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """Plain data (tuples as lists); see :func:`json_safe` for writing it."""
        data = asdict(self)
        data["betas"] = list(self.betas)
        data["q_bounds"] = list(self.q_bounds) if self.q_bounds is not None else None
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "TrainConfig":
        """The config a :meth:`to_dict` or a ``--config`` file describes.

        Raises:
            ValueError: a key is not a field (names the valid ones).
        """
        check_fields(cls, data, "training")
        data = dict(data)
        for key in ("betas", "q_bounds"):
            if data.get(key) is not None:
                data[key] = tuple(data[key])
        return cls(**data)

    def step_config(self) -> TDStepConfig:
        """The gradient step's settings."""
        return TDStepConfig(
            gamma=self.gamma, grasp_symmetry=self.grasp_symmetry, max_grad_norm=self.max_grad_norm, target_bounds=self.q_bounds
        )

    def optimizer_kwargs(self) -> dict[str, Any]:
        """Adam's settings besides the learning rate."""
        return {"weight_decay": self.weight_decay, "betas": tuple(self.betas)}


def json_safe(data: dict[str, Any]) -> dict[str, Any]:
    """``data`` with NaN floats (an uncalibrated Q*_g) as ``None``, which JSON can hold."""
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in data.items()}
