"""MPGNet on an env's action space: flat Q, Q at chosen actions, and greedy actions.

An MPG action space indexes ``(primitive, rotation, row, col)`` in C order, primitives in the
env's allowed subset of ``move, push, grasp`` (:mod:`mpg_envs.grid.actions`). :class:`MPGQFunction`
gives MPGNet's Q maps in that order, the Q of chosen actions (the training path: only each
sample's chosen rotation is computed) and the max-Q actions (the TD target's choice).

Move and grasp act inside the rough target region (:mod:`mpg_agents.network.regions`): outside it
their Q is 0 by construction, which must not win over a negative Q inside it, so choosing
masks it to -inf (:meth:`MPGQFunction.masked_flat_q`). A network may lack branches the env
allows (a grasp-only checkpoint on ``MPG-Occluded-v0``): it acts with the primitives it has
(:attr:`MPGQFunction.usable_primitives`); the others get Q = -inf and are never chosen.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import torch
from gymnasium import spaces
from torch import Tensor, nn

from mpg_agents.acting.coordination import usable_primitives
from mpg_agents.network.finger_geometry import FingerGeometry
from mpg_agents.network.mpgnet import EncodedObs, MPGNet, flat_q
from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_envs.grid.actions import check_primitives


def check_action_space(action_space: spaces.Discrete, primitives: Sequence[str], config: MPGNetConfig) -> None:
    """Fail early when ``action_space`` does not hold ``primitives`` x rotations x pixels actions."""
    r, s = config.num_rotations, config.heightmap_size
    expected = len(primitives) * r * s * s
    if int(action_space.n) != expected:
        raise ValueError(
            f"action space Discrete({action_space.n}) does not match primitives {tuple(primitives)} "
            f"x {r} rotations x {s} x {s} = {expected}"
        )


def mask_outside(q: Tensor, allowed: Tensor | None) -> Tensor:
    """``q`` with -inf where ``allowed`` (broadcast to it) is false; ``None``: unchanged."""
    return q if allowed is None else q.masked_fill(~allowed, float("-inf"))


class MPGQFunction(nn.Module):
    """MPGNet's Q over an env's flat action space.

    Args:
        net_config: the network (its ``primitives`` are the branches built).
        action_primitives: the env's primitives, in its action order.
        geometry: the env's grasp geometry (for finger masks; see :class:`~mpg_agents.network.mpgnet.MPGNet`).
    """

    def __init__(
        self, net_config: MPGNetConfig, action_primitives: Sequence[str], geometry: FingerGeometry | None = None
    ) -> None:
        super().__init__()
        self._setup(net_config, action_primitives, geometry)

    def _setup(
        self, net_config: MPGNetConfig, action_primitives: Sequence[str], geometry: FingerGeometry | None = None
    ) -> None:
        """Build the network (also called by the SB3 adapter, whose ``__init__`` is SB3's)."""
        self.action_primitives: tuple[str, ...] = check_primitives(action_primitives)
        # What a decision may choose: the env's primitives the network has a branch for.
        self.usable_primitives: tuple[str, ...] = usable_primitives(self.action_primitives, net_config.primitives)
        self.net_config = net_config
        self.mpgnet = MPGNet(net_config, geometry)

    @property
    def num_actions(self) -> int:
        """Size of the flat action space."""
        r, s = self.net_config.num_rotations, self.net_config.heightmap_size
        return len(self.action_primitives) * r * s * s

    def set_training_mode(self, mode: bool) -> None:
        """Train (batch statistics) or eval mode, as SB3's modules name it."""
        self.train(mode)

    # ------------------------------------------------------------ Q values
    def forward(self, obs: Mapping[str, Any]) -> Tensor:
        """Flat Q ``(B, P * R * H * W)`` in the env's action order (-inf for a missing branch)."""
        return flat_q(self._with_missing(self.mpgnet(obs, self.usable_primitives)), self.action_primitives)

    def q_maps(self, obs: Mapping[str, Any]) -> dict[str, Tensor]:
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
        n = self.num_actions
        if (a < 0).any() or (a >= n).any():
            raise ValueError(f"actions must lie in 0..{n - 1}, got {a.tolist()}")
        col = a % s
        row = (a // s) % s
        rot = (a // (s * s)) % r
        prim = a // (s * s * r)
        return prim, rot, row, col

    def q_values_at(self, obs: Mapping[str, Any], actions: Tensor) -> Tensor:
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
            self._with_missing({p: mask_outside(maps[p], self.mpgnet.actable(enc, p)) for p in maps}),
            self.action_primitives,
        )

    def greedy_actions(self, obs: Mapping[str, Any]) -> Tensor:
        """Max-Q actions ``(B,)`` over all usable primitives (where each may act)."""
        enc = self.mpgnet.encode(obs)
        maps = self.mpgnet.maps_from(enc, self.usable_primitives)
        return self.masked_flat_q(maps, enc).argmax(dim=1)
