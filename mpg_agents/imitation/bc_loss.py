"""The behaviour-cloning loss: a pixel-wise classification over the flat action space.

The nets' maps over every primitive, rotation and pixel, flattened in the env's action order
(:func:`mpg_agents.network.mpgnet.flat_q`), are the logits of one softmax, and the loss is the
cross-entropy of the recorded flat action (as Transporter networks train their picking and
placing maps). With :func:`sampled_rotations` the softmax runs over a sample of the rotations
that always holds the recorded one (a sampled softmax: the normaliser leaves the other
rotations out of that step). Pure functions of tensors and a seeded generator; no network, no env.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor
from torch.nn import functional as F


def _check(logits: Tensor, actions: Tensor) -> Tensor:
    """``actions`` as a ``(B,)`` int64 tensor on ``logits``' device, after the shape and range checks."""
    if logits.dim() != 2:
        raise ValueError(f"logits must be (batch, actions), got shape {tuple(logits.shape)}")
    actions = torch.as_tensor(actions, device=logits.device).long().reshape(-1)
    if actions.numel() != logits.shape[0]:
        raise ValueError(f"{logits.shape[0]} rows of logits but {actions.numel()} actions; give one action per row")
    n = logits.shape[1]
    if actions.numel() and (bool((actions < 0).any()) or bool((actions >= n).any())):
        raise ValueError(f"actions must lie in 0..{n - 1} (the flat action space), got {actions.tolist()}")
    return actions


def imitation_loss(logits: Tensor, actions: Tensor) -> Tensor:
    """Mean cross-entropy of the recorded flat ``actions`` ``(B,)`` under one softmax over each row
    of ``logits`` ``(B, A)``: ``mean_b(logsumexp(logits[b]) - logits[b, actions[b]])``.

    Raises:
        ValueError: ``logits`` not two-dimensional, a number of actions other than its rows, or
            an action outside ``0..A - 1``.
    """
    return F.cross_entropy(logits, _check(logits, actions))


def top1_accuracy(logits: Tensor, actions: Tensor) -> float:
    """The share of rows whose largest logit is the recorded action (the greedy choice copies it)."""
    actions = _check(logits, actions)
    return float((logits.argmax(dim=1) == actions).float().mean())


def sampled_rotations(
    rng: np.random.Generator, actions: np.ndarray, per_sample: int, num_rotations: int, pixels: int
) -> tuple[np.ndarray, np.ndarray]:
    """The rotations one step of a sampled softmax runs, and each recorded action's class among them.

    Args:
        rng: the run's seeded generator (the draws are part of a resumable run).
        actions: ``(B,)`` recorded flat actions over ``(primitive, rotation, pixel)`` in C order.
        per_sample: ``K``, rotations per sample: the recorded one first, then ``K - 1`` others
            drawn without replacement.
        num_rotations: ``R``, the rotations of the action space.
        pixels: ``H * W``, the pixels of one map.

    Returns:
        ``(B, K)`` rotation indices and ``(B,)`` classes into the ``(primitive, K, pixel)`` flat
        logits of those maps: ``primitive * K * pixels + pixel`` (the recorded rotation is slot 0).

    Raises:
        ValueError: ``per_sample`` outside ``1..num_rotations``, or a negative action (a primitive
            beyond the space is caught by :func:`imitation_loss`).
    """
    if not 1 <= per_sample <= num_rotations:
        raise ValueError(f"rotations per sample must lie in 1..{num_rotations}, got {per_sample}")
    actions = np.asarray(actions, dtype=np.int64).reshape(-1)
    per_primitive = num_rotations * pixels
    if actions.size and actions.min() < 0:
        raise ValueError(f"actions must be flat action indices >= 0, got {actions.tolist()}")
    primitive, rest = np.divmod(actions, per_primitive)
    recorded, pixel = np.divmod(rest, pixels)
    rotations = np.empty((actions.size, per_sample), dtype=np.int64)
    for b, k in enumerate(recorded):
        others = np.delete(np.arange(num_rotations), k)
        rotations[b, 0] = k
        rotations[b, 1:] = rng.choice(others, size=per_sample - 1, replace=False)
    return rotations, primitive * per_sample * pixels + pixel
