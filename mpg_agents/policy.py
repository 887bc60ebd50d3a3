"""Stable-Baselines3 DQN policy around MPGNet, with the paper's move/push/grasp coordination.

``stable_baselines3.DQN(MPGNetPolicy, env)`` works on every MPG env: the Q-network returns
the flat Q vector in the env's action order (C order over primitive, rotation, row, col,
primitives in the env's allowed subset of ``move, push, grasp``).

A decision (``predict``, :meth:`MPGNetPolicy.decide`) picks the primitive with
:func:`mpg_agents.coordination.choose_primitive` and then the best pixel and rotation of that
primitive's Q maps; only the branches the rule needs are computed. Move and grasp act inside
the rough target region (:mod:`mpg_agents.regions`): outside it their Q is 0 by construction,
which must not win over a negative Q inside it.

A network may lack branches the env allows (a grasp-only checkpoint on ``MPG-Occluded-v0``):
it acts with the primitives it has (:attr:`MPGQNetwork.usable_primitives`); the others get
Q = -inf in the flat vector and are never chosen.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, NamedTuple, Sequence

import torch
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from stable_baselines3.dqn.policies import DQNPolicy, QNetwork
from torch import Tensor, nn

from mpg_agents.coordination import check_coordination, choose_primitive, usable_primitives
from mpg_agents.grasp_scorer import GraspScorer
from mpg_agents.mpgnet import EncodedObs, MPGNet, flat_q
from mpg_agents.mpgnet_config import MPGNetConfig
from mpg_agents.regions import region_max
from mpg_agents.spaces import check_observation_space, resolve_primitives
from mpg_agents.weights import load_mpgnet_weights, read_checkpoint_header, save_mpgnet
from mpg_envs.actions import check_primitives, encode_action

PAPER_OPTIMIZER_KWARGS: dict[str, Any] = {"weight_decay": 2.0**-5, "betas": (0.9, 0.99)}
"""Adam settings of the paper (the learning rate, 1e-4, comes from the algorithm)."""


class Decision(NamedTuple):
    """One coordinated decision: the flat action and what it was made from."""

    action: int
    primitive: str
    rotation: int
    row: int
    col: int
    q_value: float
    grasp_score: float  # best grasp Q in the target region, NaN when the grasp net was not run
    q_maps: dict[str, Tensor]  # the (R, H, W) maps computed for this decision


class MPGQNetwork(QNetwork):
    """SB3 Q-network whose forward pass is MPGNet's flat Q vector.

    Bypasses ``QNetwork.__init__`` (it would build an MLP with one output per action, i.e.
    millions) and ``preprocess_obs``: MPGNet normalises raw uint8 colour, metric depth and the
    0/1 mask itself, so SB3 must not divide by 255 or one-hot anything.
    """

    def __init__(
        self,
        observation_space: spaces.Dict,
        action_space: spaces.Discrete,
        net_config: MPGNetConfig,
        action_primitives: Sequence[str],
        coordination: str = "workflow",
        q_star: float = float("nan"),
    ) -> None:
        BasePolicy.__init__(self, observation_space, action_space, features_extractor=None, normalize_images=False)
        check_observation_space(observation_space, net_config.heightmap_size)
        self.action_primitives = check_primitives(action_primitives)
        # What the coordination may choose: the env's primitives the network has a branch for.
        self.usable_primitives = usable_primitives(self.action_primitives, net_config.primitives)
        r, s = net_config.num_rotations, net_config.heightmap_size
        expected = len(self.action_primitives) * r * s * s
        if int(action_space.n) != expected:
            raise ValueError(
                f"action space Discrete({action_space.n}) does not match primitives {self.action_primitives} "
                f"x {r} rotations x {s} x {s} = {expected}"
            )
        self.coordination = check_coordination(coordination)
        self.net_config = net_config
        self.mpgnet = MPGNet(net_config)
        # float64 so a calibrated value such as 1.85 round-trips exactly through saves.
        self.register_buffer("q_star", torch.tensor(float(q_star), dtype=torch.float64))

    # ------------------------------------------------------------ Q values
    def forward(self, obs: PyTorchObs) -> Tensor:
        """Flat Q ``(B, P * R * H * W)`` in the env's action order (-inf for a missing branch)."""
        return flat_q(self._with_missing(self.mpgnet(obs, self.usable_primitives)), self.action_primitives)

    def q_maps(self, obs: PyTorchObs) -> dict[str, Tensor]:
        """``{primitive: (B, R, H, W)}`` for the usable primitives."""
        return self.mpgnet(obs, self.usable_primitives)

    def _with_missing(self, maps: Mapping[str, Tensor]) -> dict[str, Tensor]:
        """``maps`` plus -inf maps for the env's primitives this network has no branch for."""
        some = next(iter(maps.values()))
        return {p: maps[p] if p in maps else torch.full_like(some, float("-inf")) for p in self.action_primitives}

    def split_actions(self, actions: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Flat actions ``(B,)``/``(B, 1)`` -> primitive index, rotation, row, col tensors."""
        a = torch.as_tensor(actions).long().reshape(-1)
        s, r = self.net_config.heightmap_size, self.net_config.num_rotations
        n = int(self.action_space.n)
        if (a < 0).any() or (a >= n).any():
            raise ValueError(f"actions must lie in 0..{n - 1}, got {a.tolist()}")
        col = a % s
        row = (a // s) % s
        rot = (a // (s * s)) % r
        prim = a // (s * s * r)
        return prim, rot, row, col

    def q_values_at(self, obs: PyTorchObs, actions: Tensor) -> Tensor:
        """Q of the chosen actions ``(B, 1)``, computing only each sample's chosen rotation.

        The training path: gradients reach only the chosen (primitive, rotation) forward
        pass, and batch norm statistics come from those inputs alone.
        """
        prim, rot, row, col = self.split_actions(actions)
        lacking = sorted({self.action_primitives[i] for i in prim.tolist()} - set(self.usable_primitives))
        if lacking:
            raise ValueError(f"actions use {lacking}, for which this network has no branch ({self.usable_primitives})")
        q = self.mpgnet.chosen_q(obs, self.action_primitives, prim, rot)
        b = torch.arange(q.shape[0], device=q.device)
        return q[b, row.to(q.device), col.to(q.device)].unsqueeze(1)

    def masked_flat_q(self, maps: Mapping[str, Tensor], enc: EncodedObs) -> Tensor:
        """Flat Q for choosing actions: -inf where a primitive may not act (move/grasp outside
        their regions, grasps the finger mask bars: :meth:`MPGNet.actable`), and primitives
        without a branch -inf everywhere."""
        return flat_q(
            self._with_missing({p: self._actable(maps[p], self.mpgnet.actable(enc, p)) for p in maps}),
            self.action_primitives,
        )

    @staticmethod
    def _actable(q: Tensor, allowed: Tensor | None) -> Tensor:
        """``q`` with -inf where ``allowed`` (broadcast to it) is false; ``None``: unchanged."""
        return q if allowed is None else q.masked_fill(~allowed, float("-inf"))

    def greedy_actions(self, obs: PyTorchObs) -> Tensor:
        """Max-Q actions ``(B,)`` over all allowed primitives (region-restricted for move/grasp)."""
        enc = self.mpgnet.encode(obs)
        maps = self.mpgnet.maps_from(enc, self.usable_primitives)
        return self.masked_flat_q(maps, enc).argmax(dim=1)

    # ---------------------------------------------------------- decisions
    def decide(
        self, obs: PyTorchObs, primitive: str | None = None, forbidden: Mapping[str, Tensor] | None = None
    ) -> list[Decision]:
        """Coordinated decisions for a batch (one :class:`Decision` per sample); ``primitive``
        overrides the coordination's choice of primitive (e.g. Stage IV's final grasp);
        ``forbidden`` maps a primitive to ``(R, H, W)`` bool actions it may not take (one
        sample only; e.g. actions that already failed on this unchanged scene)."""
        batch = _batch_size(obs)
        if forbidden and batch != 1:
            raise ValueError(f"forbidden actions apply to one observation, got a batch of {batch}")
        decisions = []
        for i in range(batch):
            single = {k: v[i : i + 1] for k, v in obs.items()}
            decisions.append(self._decide_one(self.mpgnet.encode(single), primitive, forbidden))
        return decisions

    def _decide_one(
        self, enc: EncodedObs, primitive: str | None = None, forbidden: Mapping[str, Tensor] | None = None
    ) -> Decision:
        maps: dict[str, Tensor] = {}
        actable: dict[str, Tensor] = {}

        def run(p: str) -> Tensor:
            """``p``'s ``(R, H, W)`` Q maps, -inf where it may not act (each branch run once)."""
            if p not in maps:
                maps[p] = self.mpgnet.maps_from(enc, (p,))[p][0]
                allowed = self.mpgnet.actable(enc, p)
                actable[p] = self._actable(maps[p], None if allowed is None else allowed[0])
                if forbidden is not None and p in forbidden:
                    barred = torch.as_tensor(forbidden[p], dtype=torch.bool, device=actable[p].device)
                    kept = actable[p].masked_fill(barred, float("-inf"))
                    if bool(torch.isfinite(kept).any()):  # never bar every action: the best of them is still an action
                        actable[p] = kept
            return actable[p]

        if primitive is not None:
            if primitive not in self.usable_primitives:
                raise ValueError(f"primitive {primitive!r} is not allowed here; allowed: {self.usable_primitives}")
        else:
            occluded = bool(enc.occluded[0]) if enc.occluded is not None else False
            best = lambda p: float(run(p).max())  # noqa: E731
            primitive = choose_primitive(self.coordination, self.usable_primitives, occluded, float(self.q_star), best)
        q = run(primitive)
        flat = int(q.flatten().argmax())
        value = float(q.flatten()[flat])
        rot, rest = divmod(flat, q.shape[1] * q.shape[2])
        row, col = divmod(rest, q.shape[2])
        grasp_score = float(region_max(maps["grasp"][None], self.mpgnet.grasp_where(enc))[0]) if "grasp" in maps else float("nan")
        action = encode_action(self.action_primitives, primitive, rot, row, col, size=self.net_config.heightmap_size)
        return Decision(action, primitive, rot, row, col, value, grasp_score, maps)

    def _predict(self, observation: PyTorchObs, deterministic: bool = True) -> Tensor:
        # Q-greedy either way: SB3's DQN does its epsilon-greedy exploration outside the policy.
        with torch.inference_mode():
            decisions = self.decide(observation)
        device = next(iter(observation.values())).device
        return torch.tensor([d.action for d in decisions], dtype=torch.long, device=device)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = BasePolicy._get_constructor_parameters(self)
        data.update(
            net_config=self.net_config,
            action_primitives=self.action_primitives,
            coordination=self.coordination,
            q_star=float(self.q_star),
        )
        return data


class MPGNetPolicy(DQNPolicy):
    """SB3 DQN policy (online and target MPGNet) with coordination and safetensors weights.

    Args:
        observation_space: the MPG Dict space (``color``, ``depth``, ``mask``, ``occluded``);
            ``color`` may be channels-first (SB3 transposes image spaces).
        action_space: the env's pixel action space.
        lr_schedule: learning-rate schedule (from the algorithm).
        variant: ``"small"`` (CPU-friendly, default) or ``"large"`` (paper).
        primitives: the action space's primitives when it does not carry ``.primitives``.
        branches: the nets to build (default: the action primitives); a superset keeps e.g.
            the grasp net as Stage III's discriminator next to the move net.
        coordination: ``"workflow"`` (paper), ``"grasp_first"`` (lever) or ``"max_q"`` (ablation);
            see :mod:`mpg_agents.coordination`.
        q_star: the calibrated grasp threshold Q*_g; NaN until calibrated.
        net_config: ``MPGNetConfig`` or its dict overriding the variant's defaults.
        imagenet_weights: optional torchvision MobileNetV3 checkpoint to initialise every trunk.
        normalize_images: must stay ``False``: MPGNet normalises its inputs itself.
        optimizer_class, optimizer_kwargs: default Adam with the paper's weight decay 2^-5 and
            betas (0.9, 0.99).
    """

    q_net: MPGQNetwork
    q_net_target: MPGQNetwork

    def __init__(
        self,
        observation_space: spaces.Dict,
        action_space: spaces.Discrete,
        lr_schedule: Schedule,
        variant: str = "small",
        primitives: Sequence[str] | None = None,
        branches: Sequence[str] | None = None,
        coordination: str = "workflow",
        q_star: float = float("nan"),
        net_config: MPGNetConfig | Mapping[str, Any] | None = None,
        imagenet_weights: str | None = None,
        normalize_images: bool = False,
        optimizer_class: type[torch.optim.Optimizer] = torch.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
        net_arch: list[int] | None = None,
        activation_fn: type[nn.Module] = nn.ReLU,
        **unused: Any,
    ) -> None:
        if normalize_images:
            raise ValueError(
                "MPGNetPolicy needs normalize_images=False: MPGNet normalises colour (/255, ImageNet "
                "mean/std), depth and mask itself, and SB3's /255 would apply twice"
            )
        if unused:
            raise TypeError(f"MPGNetPolicy got unexpected keyword arguments {sorted(unused)}")
        self.action_primitives = resolve_primitives(action_space, primitives)
        check_coordination(coordination)
        built = check_primitives(branches) if branches is not None else self.action_primitives
        if isinstance(net_config, MPGNetConfig):
            cfg = MPGNetConfig.from_dict({**net_config.to_dict(), "primitives": list(built)})
        else:
            overrides = dict(net_config or {})
            overrides["primitives"] = tuple(built)
            if overrides.pop("variant", variant) != variant:
                raise ValueError(f"net_config variant {net_config['variant']!r} contradicts variant={variant!r}")
            cfg = MPGNetConfig.for_variant(variant, **overrides)
        self.net_config = cfg
        self.variant = cfg.variant
        self.branches = built
        self.coordination = coordination
        self._initial_q_star = float(q_star)
        self.imagenet_weights = imagenet_weights
        if optimizer_kwargs is None:
            optimizer_kwargs = dict(PAPER_OPTIMIZER_KWARGS)
        super().__init__(
            observation_space,
            action_space,
            lr_schedule,
            net_arch=net_arch,
            activation_fn=activation_fn,
            normalize_images=False,
            optimizer_class=optimizer_class,
            optimizer_kwargs=optimizer_kwargs,
        )

    def _build(self, lr_schedule: Schedule) -> None:
        self.q_net = self.make_q_net()
        if self.imagenet_weights:
            self.q_net.mpgnet.load_imagenet(self.imagenet_weights)
        self.q_net_target = self.make_q_net()
        self.q_net_target.load_state_dict(self.q_net.state_dict())
        self.q_net_target.set_training_mode(False)
        self.optimizer = self.optimizer_class(  # type: ignore[call-arg]
            self.q_net.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs
        )

    def make_q_net(self) -> MPGQNetwork:
        return MPGQNetwork(
            self.observation_space,  # type: ignore[arg-type]
            self.action_space,  # type: ignore[arg-type]
            self.net_config,
            self.action_primitives,
            self.coordination,
            self._initial_q_star,
        ).to(self.device)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        for key in ("features_extractor_class", "features_extractor_kwargs"):
            data.pop(key, None)
        data.update(
            variant=self.variant,
            primitives=self.action_primitives,
            branches=self.branches,
            coordination=self.coordination,
            q_star=self.q_star,
            net_config=self.net_config.to_dict(),
        )
        return data

    @property
    def usable_primitives(self) -> tuple[str, ...]:
        """The env's primitives this policy's network has a branch for (what it acts with)."""
        return self.q_net.usable_primitives

    # ------------------------------------------------------------ Q*_g
    @property
    def q_star(self) -> float:
        """The calibrated grasp threshold Q*_g (NaN until :meth:`set_q_star`)."""
        return float(self.q_net.q_star)

    def set_q_star(self, value: float) -> None:
        """Store a calibrated Q*_g (saved with the weights and with ``DQN.save``)."""
        value = float(value)
        for net in (self.q_net, self.q_net_target):
            net.q_star.fill_(value)

    def set_coordination(self, coordination: str) -> None:
        """Switch to another of :data:`~mpg_agents.coordination.COORDINATIONS`."""
        self.coordination = check_coordination(coordination)
        self.q_net.coordination = coordination
        self.q_net_target.coordination = coordination

    # ------------------------------------------------------- convenience
    def decide(
        self, observation: Mapping[str, Any], primitive: str | None = None, forbidden: Mapping[str, Any] | None = None
    ) -> Decision:
        """The coordinated decision for one raw env observation, with the Q maps it used;
        ``forbidden``: ``{primitive: (R, H, W) bool}`` actions not to take."""
        self.set_training_mode(False)
        obs_tensor, vectorized = self.obs_to_tensor(dict(observation))
        if vectorized and _batch_size(obs_tensor) != 1:
            raise ValueError("decide() takes one observation; use predict() for a batch")
        with torch.inference_mode():
            return self.q_net.decide(obs_tensor, primitive, forbidden)[0]

    def grasp_scorer(self) -> "GraspScorer":
        """A ``callable(obs) -> float`` for the envs' ``grasp_scorer`` (uses the online grasp net)."""
        return GraspScorer(self.q_net.mpgnet)

    # ----------------------------------------------------- safetensors
    def save_weights(self, path: str | Path) -> None:
        """Write the online network to ``path`` (safetensors + JSON header with Q*_g)."""
        save_mpgnet(self.q_net.mpgnet, path, q_star=self.q_star, extra={"coordination": self.coordination})

    def load_weights(self, path: str | Path, strict_branches: bool = True) -> dict[str, Any]:
        """Load a :meth:`save_weights` file into the online and target networks.

        Q*_g is taken from the file when it has one. Never unpickles anything.

        Raises:
            ValueError: the file holds another architecture (names the mismatch).
        """
        header = load_mpgnet_weights(self.q_net.mpgnet, path, strict_branches=strict_branches)
        self.q_net_target.mpgnet.load_state_dict(self.q_net.mpgnet.state_dict())
        if header.get("q_star") is not None:
            self.set_q_star(header["q_star"])
        return header

    @classmethod
    def from_weights(
        cls,
        path: str | Path,
        observation_space: spaces.Dict,
        action_space: spaces.Discrete,
        net_overrides: Mapping[str, Any] | None = None,
        **kwargs: Any,
    ) -> "MPGNetPolicy":
        """A policy built with the checkpoint's own configuration (variant, head, trunk depth),
        with ``net_overrides`` of settings that change no weight (e.g. ``grasp_region``); it
        coordinates as the checkpoint was trained to (its header's ``coordination``, else the
        paper's workflow) unless ``coordination`` is given."""
        header = read_checkpoint_header(path)
        kwargs.setdefault("coordination", header.get("extra", {}).get("coordination", "workflow"))
        cfg = MPGNetConfig.from_checkpoint(header["config"], **dict(net_overrides or {}))
        # Build the branches the file has that the env can use (an error names none usable).
        kwargs.setdefault("branches", usable_primitives(resolve_primitives(action_space), header["primitives"]))
        policy = cls(observation_space, action_space, lambda _: 1e-4, variant=cfg.variant, net_config=cfg, **kwargs)
        policy.load_weights(path, strict_branches=True)
        return policy


def _batch_size(obs: Mapping[str, Tensor]) -> int:
    return int(next(iter(obs.values())).shape[0])
