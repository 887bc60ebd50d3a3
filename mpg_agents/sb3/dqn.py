"""SB3 DQN for MPGNet: :class:`MPGDQN` trains with :func:`mpg_agents.learning.td_step.td_step`.

:class:`MPGDQN` changes only :meth:`DQN.train` and the defaults: each gradient step is the
same step ``mpg-train``'s learner takes (double-DQN target, chosen-pixel Huber loss, grasp
symmetry, optional branch freezing, target clamp and gradient clipping, priorities
``|Q(s, a) - y|``), and every setting the learner has comes from the same
:class:`~mpg_agents.learning.train_config.TrainConfig` (:func:`sb3_settings`).

Plain ``stable_baselines3.DQN(MPGNetPolicy, env)`` also works (it gathers the chosen pixel
from the full flat Q vector); it just runs all 16 rotations of every branch in training
mode and samples uniformly.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import numpy as np
from stable_baselines3.dqn.dqn import DQN

from mpg_agents.acting.device import resolve_device
from mpg_agents.acting.q_function import MPGQFunction
from mpg_agents.acting.spaces import finger_geometry
from mpg_agents.learning.replay import PrioritizedHeightmapReplayBuffer
from mpg_agents.learning.td_step import TDStepConfig, td_step
from mpg_agents.learning.train_config import TrainConfig
from mpg_agents.sb3.policy import MPGNetPolicy
from mpg_agents.sb3.replay import SB3HeightmapReplayBuffer

LEARNING_STARTS = 100
"""Transitions SB3 collects before its first gradient step (the learner has no such wait)."""


def sb3_settings(config: TrainConfig) -> dict[str, Any]:
    """:class:`MPGDQN` keyword arguments carrying ``config``'s settings.

    Replay capacity, batch size, learning rate, discount, epsilon start and end (annealed over
    the whole run, as ``mpg-train`` does by default), target-network sync, priority exponent,
    grasp symmetry, TD-target clamp, gradient clipping, the device, and the policy's variant,
    network settings and Adam weight decay and betas.

    Raises:
        ValueError: ``config.epsilon_decay_steps`` is set (SB3 anneals over a fraction of the
            run instead: pass ``exploration_fraction``).
    """
    if config.epsilon_decay_steps is not None:
        raise ValueError(
            "SB3 anneals epsilon over a fraction of learn()'s steps: pass exploration_fraction "
            f"instead of epsilon_decay_steps={config.epsilon_decay_steps}"
        )
    return {
        "learning_rate": config.learning_rate,
        "buffer_size": config.replay_capacity,
        "batch_size": config.batch_size,
        "gamma": config.gamma,
        "target_update_interval": config.target_update_every,
        "exploration_fraction": 1.0,
        "exploration_initial_eps": config.epsilon_start,
        "exploration_final_eps": config.epsilon_end,
        "replay_buffer_kwargs": {"alpha": config.priority_alpha},
        "grasp_symmetry": config.grasp_symmetry,
        "target_bounds": config.q_bounds,
        "max_grad_norm": config.max_grad_norm,
        "device": config.device,
        "policy_kwargs": {
            "variant": config.variant,
            "net_config": dict(config.net_config),
            "optimizer_kwargs": config.optimizer_kwargs(),
        },
    }


class MPGDQN(DQN):
    """SB3 ``DQN`` with MPGNet's training step and ``mpg-train``'s settings as defaults.

    Every keyword SB3's ``DQN`` takes may be given; those not given come from ``config``
    (default: ``TrainConfig()``, the paper's algorithm where it gives one) through
    :func:`sb3_settings`, ``learning_starts`` from :data:`LEARNING_STARTS`, the replay buffer
    is the prioritised compact one. ``policy_kwargs`` are merged over the config's.

    Args:
        policy: the policy class (default :class:`~mpg_agents.sb3.policy.MPGNetPolicy`).
        env: the env (or its id).
        config: the training settings the defaults come from.
        trainable: the branches that learn (``None``: all); the rest are frozen.
        **kwargs: SB3 ``DQN`` keywords, and the training step's: ``grasp_symmetry`` (also
            train grasp rotation ``r + R/2`` with the target of ``r``), ``target_bounds`` (clamp
            TD targets to ``(low, high)``; ``None``: no clamp), ``max_grad_norm`` (clip the
            gradient's norm; ``None``: no clipping, as in the paper; SB3's own default is 10).
    """

    def __init__(
        self,
        policy: str | type[MPGNetPolicy] = MPGNetPolicy,
        env: Any = None,
        config: TrainConfig | None = None,
        trainable: Sequence[str] | None = None,
        **kwargs: Any,
    ) -> None:
        settings = sb3_settings(config if config is not None else TrainConfig())
        settings["policy_kwargs"] = {**settings["policy_kwargs"], **(kwargs.pop("policy_kwargs", None) or {})}
        if env is not None and not isinstance(env, str) and hasattr(env.unwrapped, "config"):
            settings["policy_kwargs"].setdefault("geometry", finger_geometry(env))  # the finger masks of this env
        settings.update(learning_starts=LEARNING_STARTS, replay_buffer_class=SB3HeightmapReplayBuffer)
        settings.update(kwargs)
        settings["device"] = resolve_device(settings["device"])  # auto | cpu | cuda, with a clear error for CUDA without one
        buffer_class = settings["replay_buffer_class"]
        if not (isinstance(buffer_class, type) and issubclass(buffer_class, PrioritizedHeightmapReplayBuffer)):
            settings.pop("replay_buffer_kwargs")  # the priority exponent is the prioritised buffer's alone
        self.step_config = TDStepConfig(
            gamma=settings["gamma"],
            grasp_symmetry=settings.pop("grasp_symmetry"),
            max_grad_norm=settings["max_grad_norm"],
            target_bounds=settings.pop("target_bounds"),
        )
        self.trainable = tuple(trainable) if trainable is not None else None
        super().__init__(policy, env, **settings)  # max_grad_norm: only td_step reads it

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        losses, surprises = [], []
        for _ in range(gradient_steps):
            data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            result = td_step(
                cast(MPGQFunction, self.q_net),
                cast(MPGQFunction, self.q_net_target),
                self.policy.optimizer,
                data,
                self.step_config,
                self.trainable,
                self.replay_buffer,
            )
            if result.trained:
                losses.append(result.loss)
                surprises.append(float(result.surprise.mean()))
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        if losses:
            self.logger.record("train/loss", float(np.mean(losses)))
            self.logger.record("train/surprise", float(np.mean(surprises)))
