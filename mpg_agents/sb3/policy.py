"""SB3 DQN policy around the MPGNet agent.

``stable_baselines3.DQN(MPGNetPolicy, env)`` works on every MPG env: the Q-network returns the
flat Q vector in the env's action order, and the policy acts as
:class:`~mpg_agents.acting.agent.MPGAgent` does (:class:`~mpg_agents.acting.agent.MPGAgentBase` over its online
network, coordination and Q*_g); the target network is SB3's.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast

import torch
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from stable_baselines3.dqn.policies import DQNPolicy, QNetwork
from torch import Tensor, nn

from mpg_agents.acting.agent import MPGAgentBase
from mpg_agents.acting.agent_settings import AgentSettings
from mpg_agents.acting.grasp_threshold import GraspThreshold
from mpg_agents.acting.q_function import MPGQFunction, check_action_space
from mpg_agents.acting.spaces import check_observation_space
from mpg_agents.learning.train_config import TrainConfig
from mpg_agents.network.finger_geometry import FingerGeometry
from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_envs.grid.actions import check_primitives

DEFAULTS = TrainConfig()
"""``mpg-train``'s settings, where the adapter's defaults come from."""


class MPGQNetwork(MPGQFunction, QNetwork):  # type: ignore[misc]  # forward: MPGNet's, not the MLP's
    """:class:`~mpg_agents.acting.q_function.MPGQFunction` as SB3's ``QNetwork``: its forward pass is
    MPGNet's flat Q vector.

    Bypasses ``QNetwork.__init__`` (it would build an MLP with one output per action, i.e.
    millions) and ``preprocess_obs``: MPGNet normalises raw uint8 colour, metric depth and the
    0/1 mask itself, so SB3 must not divide by 255 or one-hot anything.

    Args:
        observation_space: the MPG Dict space.
        action_space: the env's pixel action space.
        net_config: the network.
        action_primitives: the action space's primitives, in its order.
        geometry: the env's grasp geometry (for finger masks).
    """

    def __init__(
        self,
        observation_space: spaces.Dict,
        action_space: spaces.Discrete,
        net_config: MPGNetConfig,
        action_primitives: Sequence[str],
        geometry: FingerGeometry | None = None,
    ) -> None:
        BasePolicy.__init__(self, observation_space, action_space, features_extractor=None, normalize_images=False)
        check_observation_space(observation_space, net_config.heightmap_size)
        check_action_space(action_space, check_primitives(action_primitives), net_config)
        self._setup(net_config, action_primitives, geometry)

    def _predict(self, observation: PyTorchObs, deterministic: bool = True) -> Tensor:
        # The max-Q action where each primitive may act (MPGNetPolicy decides with the coordination).
        return self.greedy_actions(cast(dict[str, Tensor], observation))  # a Dict space's observation

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = BasePolicy._get_constructor_parameters(self)
        data.update(net_config=self.net_config, action_primitives=self.action_primitives, geometry=self.mpgnet.geometry)
        return data


class MPGNetPolicy(MPGAgentBase, DQNPolicy):
    """SB3 DQN policy (online and target MPGNet) with coordination, Q*_g and safetensors weights:
    it decides, holds Q*_g and saves weights as :class:`~mpg_agents.acting.agent.MPGAgent` does.

    Args:
        observation_space: the MPG Dict space (``color``, ``depth``, ``mask``, ``occluded``);
            ``color`` may be channels-first (SB3 transposes image spaces).
        action_space: the env's pixel action space.
        lr_schedule: learning-rate schedule (from the algorithm).
        settings: the fields of :class:`~mpg_agents.acting.agent_settings.AgentSettings` (variant,
            primitives, branches, coordination, q_star, net_config, imagenet_weights, geometry),
            as :meth:`~mpg_agents.acting.agent.MPGAgent.build` takes them.
        normalize_images: must stay ``False``: MPGNet normalises its inputs itself.
        optimizer_class: default Adam.
        optimizer_kwargs: default: ``mpg-train``'s weight decay and betas (the paper's 2^-5 and
            (0.9, 0.99)).
        net_arch: accepted for SB3's signature; unused.
        activation_fn: accepted for SB3's signature; unused.
    """

    q_net: MPGQNetwork
    q_net_target: MPGQNetwork

    def __init__(
        self,
        observation_space: spaces.Dict,
        action_space: spaces.Discrete,
        lr_schedule: Schedule,
        normalize_images: bool = False,
        optimizer_class: type[torch.optim.Optimizer] = torch.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
        net_arch: list[int] | None = None,
        activation_fn: type[nn.Module] = nn.ReLU,
        **settings: Any,
    ) -> None:
        if normalize_images:
            raise ValueError(
                "MPGNetPolicy needs normalize_images=False: MPGNet normalises colour (/255, ImageNet "
                "mean/std), depth and mask itself, and SB3's /255 would apply twice"
            )
        self.settings = AgentSettings(**settings)
        resolved = self.settings.resolve(observation_space, action_space)
        self.action_primitives = resolved.action_primitives
        self.coordination = self.settings.coordination
        self.net_config = resolved.net_config
        self.branches = self.net_config.primitives
        self.variant = self.net_config.variant
        self.geometry = resolved.geometry
        super().__init__(
            observation_space,
            action_space,
            lr_schedule,
            net_arch=net_arch,
            activation_fn=activation_fn,
            normalize_images=False,
            optimizer_class=optimizer_class,
            optimizer_kwargs=DEFAULTS.optimizer_kwargs() if optimizer_kwargs is None else optimizer_kwargs,
        )
        self.threshold = GraspThreshold(self.settings.q_star)  # a module: SB3's save keeps Q*_g

    def _build(self, lr_schedule: Schedule) -> None:
        self.q_net = self.make_q_net()
        if self.settings.imagenet_weights:
            self.q_net.mpgnet.load_imagenet(self.settings.imagenet_weights)
        self.q_net_target = self.make_q_net()
        self.q_net_target.load_state_dict(self.q_net.state_dict())
        self.q_net_target.set_training_mode(False)
        self.optimizer = self.optimizer_class(  # type: ignore[call-arg]
            self.q_net.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs
        )

    def make_q_net(self) -> MPGQNetwork:
        """A new Q-network for this policy's spaces and configuration."""
        return MPGQNetwork(
            self.observation_space,  # type: ignore[arg-type]
            self.action_space,  # type: ignore[arg-type]
            self.net_config,
            self.action_primitives,
            self.geometry,
        ).to(self.device)

    def _predict(self, observation: PyTorchObs, deterministic: bool = True) -> Tensor:
        # Q-greedy either way: SB3's DQN does its epsilon-greedy exploration outside the policy.
        with torch.inference_mode():
            obs = cast(dict[str, Tensor], observation)  # a Dict space's observation
            decisions = self.decide_batch(obs)
        device = next(iter(obs.values())).device
        return torch.tensor([d.action for d in decisions], dtype=torch.long, device=device)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        for key in ("features_extractor_class", "features_extractor_kwargs"):
            data.pop(key, None)
        # The settings as built (weights come from the saved state, not ImageNet again).
        data.update(
            self.settings.replace(
                primitives=self.action_primitives,
                branches=self.branches,
                coordination=self.coordination,
                q_star=self.q_star,
                net_config=self.net_config,
                imagenet_weights=None,
                geometry=self.geometry,
            ).to_dict()
        )
        return data

    # ----------------------------------------------------- safetensors
    def load_weights(self, path: str | Path, strict_branches: bool = True) -> dict[str, Any]:
        """Load a :meth:`save_weights` file into the online and target networks; Q*_g is taken
        from the file when it has one. Never unpickles anything.

        Raises:
            ValueError: the file holds another architecture (names the mismatch).
        """
        header = super().load_weights(path, strict_branches=strict_branches)
        self.q_net_target.mpgnet.load_state_dict(self.q_net.mpgnet.state_dict())
        return header

    @classmethod
    def build(cls, observation_space: spaces.Dict, action_space: spaces.Discrete, **settings: Any) -> MPGNetPolicy:
        """A policy for an env's spaces with ``mpg-train``'s learning rate (``settings``: the
        constructor's)."""
        return cls(observation_space, action_space, lambda _: DEFAULTS.learning_rate, **settings)
