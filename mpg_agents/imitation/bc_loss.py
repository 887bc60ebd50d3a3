"""The behaviour-cloning loss: a pixel-wise classification over the flat action space.

The nets' maps over every primitive, rotation and pixel, flattened in the env's action order
(:func:`mpg_agents.network.mpgnet.flat_q`), are the logits of one softmax, and the loss is the
cross-entropy of the recorded flat action (as Transporter networks train their picking and
placing maps). Pure functions of tensors; no network, no env.
"""

from __future__ import annotations

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
