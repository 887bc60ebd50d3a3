"""The MPGNet agent: the network on an env's action space, deciding with the paper's
move/push/grasp coordination and Q*_g. No Stable-Baselines3 in it.

:class:`MPGAgent` is what ``mpg-train``'s learner trains and acts with, what ``mpg-eval`` and
``mpg-calibrate`` load (:mod:`mpg_agents.evaluation.policy_zoo`), and what the SB3 adapter
(:mod:`mpg_agents.sb3`) wraps. A decision (:meth:`MPGAgent.decide`) picks the primitive with
:func:`mpg_agents.acting.coordination.choose_primitive` and then the best pixel and rotation of that
primitive's Q maps (:mod:`mpg_agents.acting.decision`).

Its parts: :attr:`MPGAgent.q_net` (:class:`~mpg_agents.acting.q_function.MPGQFunction`, holding the
:class:`~mpg_agents.network.mpgnet.MPGNet`), the coordination rule, and :attr:`MPGAgent.threshold`
(:class:`~mpg_agents.acting.grasp_threshold.GraspThreshold`, the Q*_g it decides with).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

import numpy as np
import torch
from gymnasium import spaces
from torch import Tensor, nn

from mpg_agents.acting.agent_settings import AgentSettings, agent_net_config  # noqa: F401  (agent_net_config: re-exported)
from mpg_agents.acting.coordination import check_coordination, usable_primitives
from mpg_agents.acting.decision import Decision, alternatives, decide
from mpg_agents.acting.discriminator import Discriminator
from mpg_agents.acting.grasp_threshold import GraspThreshold, from_header
from mpg_agents.acting.q_function import MPGQFunction
from mpg_agents.acting.spaces import resolve_primitives
from mpg_agents.acting.weights import load_mpgnet_weights, read_checkpoint_header, save_mpgnet
from mpg_agents.network.mpgnet_config import MPGNetConfig


def checkpoint_settings(
    path: str | Path, action_space: spaces.Discrete, net_overrides: Mapping[str, Any] | None = None, **kwargs: Any
) -> dict[str, Any]:
    """Keyword arguments that rebuild a checkpoint's network for ``action_space``.

    The checkpoint's own configuration (variant, head, trunk depth) with ``net_overrides`` of
    settings that change no weight (e.g. ``grasp_region``); the branches it has that the env can
    use; the coordination it records (else the paper's workflow). ``kwargs`` win over the file.

    Raises:
        ValueError: the checkpoint has no branch this env can use.
    """
    header = read_checkpoint_header(path)
    kwargs.setdefault("coordination", header.get("extra", {}).get("coordination", "workflow"))
    cfg = MPGNetConfig.from_checkpoint(header["config"], **dict(net_overrides or {}))
    kwargs.setdefault("branches", usable_primitives(resolve_primitives(action_space), header["primitives"]))
    return {**kwargs, "variant": cfg.variant, "net_config": cfg}


def batch_observation(observation: Mapping[str, Any], device: torch.device | str = "cpu") -> tuple[dict[str, Tensor], int]:
    """Raw env observation(s) as tensors with a leading batch axis on ``device``, and the batch size.

    One observation (an ``(H, W, 3)`` or ``(3, H, W)`` colour heightmap) gains the axis; a batch
    keeps its own.
    """
    single = np.ndim(observation["color"]) == 3
    out = {}
    for key, value in observation.items():
        t = value if isinstance(value, Tensor) else torch.as_tensor(np.asarray(value))
        out[key] = (t[None] if single else t).to(device)
    return out, int(out["color"].shape[0])


class MPGAgentBase:
    """What an MPGNet agent does with ``q_net`` (:class:`~mpg_agents.acting.q_function.MPGQFunction`),
    ``threshold`` (:class:`~mpg_agents.acting.grasp_threshold.GraspThreshold`) and ``coordination``:
    decide, hold Q*_g, save and load weights. :class:`MPGAgent` and the SB3 adapter's
    ``MPGNetPolicy`` both act through it.
    """

    q_net: MPGQFunction
    threshold: GraspThreshold
    coordination: str

    if TYPE_CHECKING:  # each class has its own (a property): declared for the checker only

        @property
        def device(self) -> torch.device: ...

    @classmethod
    def build(cls, observation_space: spaces.Dict, action_space: spaces.Discrete, **settings: Any) -> Self:
        """A fresh one for an env's spaces (``settings``: the fields of
        :class:`~mpg_agents.acting.agent_settings.AgentSettings`)."""
        raise NotImplementedError

    @classmethod
    def from_weights(
        cls,
        path: str | Path,
        observation_space: spaces.Dict,
        action_space: spaces.Discrete,
        net_overrides: Mapping[str, Any] | None = None,
        **kwargs: Any,
    ) -> Self:
        """One built with a checkpoint's own configuration and loaded from it
        (:func:`checkpoint_settings`; ``kwargs`` go to :meth:`build`)."""
        agent = cls.build(observation_space, action_space, **checkpoint_settings(path, action_space, net_overrides, **kwargs))
        agent.load_weights(path, strict_branches=True)
        return agent

    @property
    def usable_primitives(self) -> tuple[str, ...]:
        """The env's primitives the network has a branch for (what it acts with)."""
        return self.q_net.usable_primitives

    # ------------------------------------------------------------------ Q*_g
    @property
    def q_star(self) -> float | None:
        """The Q*_g it decides with (``None`` before any)."""
        return self.threshold.get()

    def set_q_star(self, value: float | None) -> None:
        """Decide with ``value`` as Q*_g from now on (saved with the weights; ``None``: none)."""
        self.threshold.set(value)

    def set_coordination(self, coordination: str) -> None:
        """Switch to another of :data:`~mpg_agents.acting.coordination.COORDINATIONS`."""
        self.coordination = check_coordination(coordination)

    # -------------------------------------------------------------- decisions
    def decide(
        self, observation: Mapping[str, Any], primitive: str | None = None, forbidden: Mapping[str, Any] | None = None
    ) -> Decision:
        """The coordinated decision for one raw env observation, with the Q maps it used.

        Args:
            observation: one observation (numpy arrays or tensors).
            primitive: use this primitive instead of the coordination's choice.
            forbidden: ``{primitive: (R, H, W) bool}`` actions not to take.

        Raises:
            ValueError: a batch of several observations, or a ``primitive`` not usable here.
        """
        self.q_net.set_training_mode(False)
        obs, batch = batch_observation(observation, self.device)
        if batch != 1:
            raise ValueError("decide() takes one observation; use decide_batch() for a batch")
        with torch.inference_mode():
            return self.decide_batch(obs, primitive, forbidden)[0]

    def decide_batch(
        self, obs: Mapping[str, Tensor], primitive: str | None = None, forbidden: Mapping[str, Any] | None = None
    ) -> list[Decision]:
        """Coordinated decisions for a batch of observation tensors (see :func:`~mpg_agents.acting.decision.decide`)."""
        return decide(self.q_net, obs, self.coordination, self.q_star, primitive, forbidden)

    def alternatives(
        self, observation: Mapping[str, Any], primitive: str, k: int, spacing_px: float, taken: tuple[int, int] | None = None
    ) -> list[int]:
        """Up to ``k`` flat ``primitive`` actions away from one taken at pixel ``taken`` (if any): the
        best of its Q maps at places ``spacing_px`` apart (:func:`~mpg_agents.acting.decision.spaced_best`),
        for one raw env observation. A trainer tries them in the simulation to label them."""
        self.q_net.set_training_mode(False)
        obs, _ = batch_observation(observation, self.device)
        with torch.inference_mode():  # alternatives() refuses a batch of several
            return alternatives(self.q_net, obs, primitive, k, spacing_px, taken)

    def discriminator(self) -> Discriminator:
        """A ``callable(obs) -> float`` for the envs' ``grasp_scorer`` (uses the grasp net)."""
        return Discriminator(self.q_net.mpgnet)

    # ------------------------------------------------------------- weights
    def save_weights(self, path: str | Path, extra: Mapping[str, Any] | None = None) -> None:
        """Write the network to ``path``: safetensors with a JSON header holding Q*_g, the
        coordination and ``extra``."""
        save_mpgnet(
            self.q_net.mpgnet, path, q_star=self.q_star, extra={**dict(extra or {}), "coordination": self.coordination}
        )

    def load_weights(self, path: str | Path, strict_branches: bool = True) -> dict[str, Any]:
        """Load a :meth:`save_weights` file; Q*_g is taken from it when it has one. Returns its
        header. Never unpickles anything.

        Raises:
            ValueError: the file holds another architecture (names the mismatch).
        """
        header = load_mpgnet_weights(self.q_net.mpgnet, path, strict_branches=strict_branches)
        if header.get("q_star") is not None:
            self.set_q_star(from_header(header))
        return header


class MPGAgent(MPGAgentBase):
    """MPGNet acting with the coordination and Q*_g (greedy; exploration is the learner's).

    Args:
        q_net: the network on the env's action space.
        coordination: one of :data:`~mpg_agents.acting.coordination.COORDINATIONS`
            (``"workflow"``: the paper's; ``"max_q"``: its ablation); see
            :mod:`mpg_agents.acting.coordination`.
        threshold: the Q*_g it decides with (default: a new, uncalibrated one).

    Build one with :meth:`build` (a fresh network) or :meth:`from_weights` (a checkpoint).
    """

    def __init__(self, q_net: MPGQFunction, coordination: str = "workflow", threshold: GraspThreshold | None = None) -> None:
        self.q_net = q_net
        self.coordination = check_coordination(coordination)
        self.threshold = threshold if threshold is not None else GraspThreshold()

    @classmethod
    def build(cls, observation_space: spaces.Dict, action_space: spaces.Discrete, **settings: Any) -> MPGAgent:
        """A fresh agent for an env's spaces.

        Args:
            observation_space: the MPG Dict space (``color``, ``depth``, ``mask``, ``occluded``).
            action_space: the env's pixel action space.
            settings: the fields of :class:`~mpg_agents.acting.agent_settings.AgentSettings`
                (variant, primitives, branches, coordination, q_star, net_config,
                imagenet_weights, geometry).

        Raises:
            ValueError: the spaces are not MPG's, or a setting is unknown.
        """
        built = AgentSettings(**settings)
        resolved = built.resolve(observation_space, action_space)
        q_net = MPGQFunction(resolved.net_config, resolved.action_primitives, resolved.geometry)
        if built.imagenet_weights:
            q_net.mpgnet.load_imagenet(built.imagenet_weights)
        return cls(q_net, built.coordination, GraspThreshold(built.q_star))

    # ------------------------------------------------------------ properties
    @property
    def net_config(self) -> MPGNetConfig:
        """The network's configuration."""
        return self.q_net.net_config

    @property
    def variant(self) -> str:
        """``"small"`` or ``"large"``."""
        return self.net_config.variant

    @property
    def branches(self) -> tuple[str, ...]:
        """The nets the agent has."""
        return self.q_net.mpgnet.primitives

    @property
    def action_primitives(self) -> tuple[str, ...]:
        """The env's primitives, in its action order."""
        return self.q_net.action_primitives

    @property
    def device(self) -> torch.device:
        """Where the network's tensors are."""
        return next(self.parameters()).device

    def to(self, device: torch.device | str) -> MPGAgent:
        """Move the network (and Q*_g's buffer) to ``device``; returns the agent."""
        self.q_net.to(device)
        self.threshold.to(device)
        return self

    def parameters(self) -> Iterator[nn.Parameter]:
        """The network's parameters (what an optimiser trains)."""
        return self.q_net.parameters()
