"""One gradient step of MPGNet's deep Q-learning, shared by ``mpg-train`` and SB3's ``MPGDQN``.

On a sampled batch (paper, Sections III-C and Training Details):

1. double-DQN target ``y = r + gamma * (1 - done) * Q_target(s', argmax_a Q(s', a))``
   (:func:`td_targets`: the online net picks ``a'`` among the allowed actions, the target net
   evaluates it; terminal samples skip the next-state passes), optionally clamped to the
   returns the rewards allow (:attr:`TDStepConfig.target_bounds`);
2. transitions whose primitive is frozen (not in ``active``) are left out of the loss;
3. grasp symmetry: a parallel-jaw grasp at rotation ``r`` is the grasp at ``r + 8``, so each
   grasp sample also trains the turned rotation with the same target;
4. ``Q(s, a)`` of only the chosen primitive and rotation (the chosen pixel), Huber loss;
5. optional gradient-norm clipping (:attr:`TDStepConfig.max_grad_norm`), Adam step;
6. priorities of the sampled transitions set to ``|Q(s, a) - y|`` (0 for a frozen one).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor
from torch.nn import functional as F

from mpg_agents.acting.q_function import MPGQFunction
from mpg_envs.grid.primitive_specs import GRASP


@dataclass(frozen=True)
class TDStepConfig:
    """How a gradient step trains.

    Attributes:
        gamma: discount (paper: 0.5); a batch may carry its own per-sample discounts instead.
        grasp_symmetry: also train grasp rotation ``r + R/2`` with the target of ``r``.
        max_grad_norm: clip the gradient's global norm to this; ``None`` = no clipping. The
            paper names no clipping, so none is the default; SB3's ``DQN``
            clips at 10 (its ``max_grad_norm`` default), which this project's SB3 path used
            before both paths shared this step.
        target_bounds: ``(low, high)``: clamp the TD targets to this range; ``None`` = no
            clamp (the paper). With rewards in ``[r_min, r_max]`` every return lies in
            ``[r_min, r_max] / (1 - gamma)`` (``[-1, 2]`` for MPG's rewards at gamma 0.5); a
            target outside it is the max-over-800k-actions bias of a young network
            bootstrapping from itself, which inflated Q*_g to 6.3 after Stage I.
    """

    gamma: float = 0.5
    grasp_symmetry: bool = True
    max_grad_norm: float | None = None
    target_bounds: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.target_bounds is not None:
            low, high = (float(v) for v in self.target_bounds)
            if not low < high:
                raise ValueError(f"target_bounds must be (low, high) with low < high, got {self.target_bounds}")
            object.__setattr__(self, "target_bounds", (low, high))
        if self.max_grad_norm is not None and not self.max_grad_norm > 0:
            raise ValueError(f"max_grad_norm must be positive or None, got {self.max_grad_norm}")


@dataclass(frozen=True)
class TDStepResult:
    """What one step did: the loss (NaN when every sample was frozen) and each sample's surprise."""

    loss: float
    surprise: np.ndarray  # (B,) |Q(s, a) - y| per sampled transition; 0 for frozen ones

    @property
    def trained(self) -> bool:
        return not math.isnan(self.loss)


def td_targets(
    q_net: MPGQFunction,
    q_net_target: MPGQFunction,
    next_observations: dict[str, Tensor],
    rewards: Tensor,
    dones: Tensor,
    gamma: float | Tensor,
    bounds: tuple[float, float] | None = None,
) -> Tensor:
    """Double-DQN targets ``(B, 1)``: the online net picks ``a'``, the target net evaluates it.

    The online net picks the max-Q action over all allowed primitives (move/grasp inside the
    target region) in eval mode, so the next-state pass neither uses nor updates batch-norm
    batch statistics; only the chosen rotation goes through the target net. Terminal samples
    (``done = 1``) skip both passes: the all-rotation greedy pass is most of a gradient step's
    cost, and Stage II ends on every success.
    """
    with torch.no_grad():
        rewards, dones = rewards.reshape(-1, 1), dones.reshape(-1, 1)
        next_q = torch.zeros_like(rewards)
        live = torch.nonzero(dones[:, 0] < 1).flatten()
        if live.numel():
            live_obs = {k: v[live] for k, v in next_observations.items()}
            was_training = q_net.training
            q_net.set_training_mode(False)
            try:
                next_actions = q_net.greedy_actions(live_obs)
            finally:
                q_net.set_training_mode(was_training)
            next_q[live] = q_net_target.q_values_at(live_obs, next_actions).to(next_q.dtype)
        targets = rewards + (1.0 - dones) * gamma * next_q
        return targets if bounds is None else targets.clamp(*bounds)


def td_step(
    q_net: MPGQFunction,
    q_net_target: MPGQFunction,
    optimizer: torch.optim.Optimizer,
    batch: Any,
    config: TDStepConfig = TDStepConfig(),
    active: Sequence[str] | None = None,
    replay: Any = None,
) -> TDStepResult:
    """One gradient step on ``batch`` (SB3 replay samples: observations, actions, ...).

    Args:
        q_net: the online network (:class:`~mpg_agents.acting.q_function.MPGQFunction`).
        q_net_target: the target network (:class:`~mpg_agents.acting.q_function.MPGQFunction`).
        optimizer: over ``q_net``'s parameters.
        batch: SB3 ``DictReplayBufferSamples``; per-sample ``discounts`` replace ``gamma`` when
            present; ``indices`` (prioritised buffers) are where priorities are written.
        config: discount, grasp symmetry, gradient clipping.
        active: the primitives whose samples train (``None``: all); the rest are frozen.
        replay: the buffer to update priorities in (skipped when ``None`` or it has no
            ``update_priorities`` or the batch no ``indices``).
    """
    primitives = q_net.action_primitives
    actions = batch.actions.reshape(-1).long()
    discounts = getattr(batch, "discounts", None)
    gamma = discounts if discounts is not None else config.gamma
    targets = td_targets(q_net, q_net_target, batch.next_observations, batch.rewards, batch.dones, gamma, config.target_bounds)
    prim, rot, _, _ = q_net.split_actions(actions)
    surprise = np.zeros(len(actions))
    keep = [i for i, p in enumerate(prim.tolist()) if active is None or primitives[p] in active]
    if not keep:
        return TDStepResult(float("nan"), surprise)  # every sampled transition is frozen
    sel = torch.tensor(keep, dtype=torch.long, device=actions.device)
    obs = {k: v[sel] for k, v in batch.observations.items()}
    acts, ys = actions[sel], targets[sel]
    if config.grasp_symmetry and GRASP in primitives:
        obs, acts, ys = _with_turned_grasps(q_net, obs, acts, ys, prim[sel], rot[sel])
    q_net.set_training_mode(True)
    q = q_net.q_values_at(obs, acts)
    loss = F.smooth_l1_loss(q, ys)
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    if config.max_grad_norm is not None:
        torch.nn.utils.clip_grad_norm_(q_net.parameters(), config.max_grad_norm)
    optimizer.step()
    surprise[keep] = (q[: len(sel)] - ys[: len(sel)]).abs().detach().reshape(-1).cpu().numpy()
    indices = getattr(batch, "indices", None)
    if replay is not None and indices is not None and hasattr(replay, "update_priorities"):
        replay.update_priorities(indices, surprise)
    return TDStepResult(float(loss.detach()), surprise)


def _with_turned_grasps(
    q_net: MPGQFunction, obs: dict[str, Tensor], acts: Tensor, ys: Tensor, prim: Tensor, rot: Tensor
) -> tuple[dict[str, Tensor], Tensor, Tensor]:
    """The batch plus, for every grasp sample, the same grasp at the rotation turned by 180 degrees."""
    sym = torch.nonzero(prim == q_net.action_primitives.index(GRASP)).flatten()
    if not sym.numel():
        return obs, acts, ys
    half = q_net.net_config.num_rotations // 2
    size = q_net.net_config.heightmap_size
    turned = acts[sym] + torch.where(rot[sym] < half, 1, -1) * half * size * size
    obs = {k: torch.cat([v, v[sym]]) for k, v in obs.items()}
    return obs, torch.cat([acts, turned]), torch.cat([ys, ys[sym]])
