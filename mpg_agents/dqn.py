"""SB3 DQN for MPGNet: :class:`MPGDQN` trains with :func:`mpg_agents.td_step.td_step`.

:class:`MPGDQN` changes only :meth:`DQN.train` (and the paper's defaults): each gradient step
is the same step ``mpg-train``'s learner takes (double-DQN target, chosen-pixel Huber loss,
grasp symmetry, optional branch freezing and gradient clipping, priorities ``|Q(s, a) - y|``).

Plain ``stable_baselines3.DQN(MPGNetPolicy, env)`` also works (it gathers the chosen pixel
from the full flat Q vector); it just runs all 16 rotations of every branch in training
mode and samples uniformly.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from stable_baselines3.dqn.dqn import DQN

from mpg_agents.policy import MPGNetPolicy
from mpg_agents.replay import PrioritizedHeightmapReplayBuffer
from mpg_agents.td_step import TDStepConfig, td_step


class MPGDQN(DQN):
    """SB3 ``DQN`` with MPGNet's training step and the paper's defaults.

    Defaults (paper, Training Details): Adam lr 1e-4 (weight decay and betas in the
    policy), gamma 0.5, epsilon 0.5 annealed to 0.1, the prioritised compact replay buffer.
    Choices of ours where the paper is silent: epsilon is annealed over the first half of
    training, ``batch_size`` is 4 (every sample is a full rotated heightmap pass) and the
    target net is synced every 100 steps (SB3's 10 000 is far beyond an MPG training run).

    ``grasp_symmetry``, ``trainable`` (the branches that learn; ``None``: all) and
    ``max_grad_norm`` (``None``: no clipping, as in the paper; SB3's own default is 10) go to
    :class:`~mpg_agents.td_step.TDStepConfig` and :func:`~mpg_agents.td_step.td_step`.
    """

    def __init__(
        self,
        policy: str | type[MPGNetPolicy] = MPGNetPolicy,
        env: Any = None,
        learning_rate: float = 1e-4,
        buffer_size: int = 10_000,
        learning_starts: int = 100,
        batch_size: int = 4,
        gamma: float = 0.5,
        target_update_interval: int = 100,
        exploration_fraction: float = 0.5,
        exploration_initial_eps: float = 0.5,
        exploration_final_eps: float = 0.1,
        replay_buffer_class: type | None = PrioritizedHeightmapReplayBuffer,
        max_grad_norm: float | None = None,
        grasp_symmetry: bool = True,
        trainable: Sequence[str] | None = None,
        **kwargs: Any,
    ) -> None:
        self.step_config = TDStepConfig(gamma=gamma, grasp_symmetry=grasp_symmetry, max_grad_norm=max_grad_norm)
        self.trainable = tuple(trainable) if trainable is not None else None
        super().__init__(
            policy,
            env,
            learning_rate=learning_rate,
            buffer_size=buffer_size,
            learning_starts=learning_starts,
            batch_size=batch_size,
            gamma=gamma,
            target_update_interval=target_update_interval,
            exploration_fraction=exploration_fraction,
            exploration_initial_eps=exploration_initial_eps,
            exploration_final_eps=exploration_final_eps,
            replay_buffer_class=replay_buffer_class,
            max_grad_norm=max_grad_norm,  # type: ignore[arg-type]  # only td_step reads it
            **kwargs,
        )

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        losses, surprises = [], []
        for _ in range(gradient_steps):
            data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            result = td_step(
                self.q_net, self.q_net_target, self.policy.optimizer, data, self.step_config, self.trainable, self.replay_buffer
            )
            if result.trained:
                losses.append(result.loss)
                surprises.append(float(result.surprise.mean()))
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        if losses:
            self.logger.record("train/loss", float(np.mean(losses)))
            self.logger.record("train/surprise", float(np.mean(surprises)))
