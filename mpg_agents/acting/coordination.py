"""Which primitive to use: the paper's coordination of the move, push and grasp nets.

Pure functions of the Q values, the occlusion bit and Q*_g; no network, no env. The caller
passes ``best_q(primitive)``, the largest Q of that primitive over the pixels where it may act
(move and grasp: inside the rough target region), and it is asked only for the primitives
the rule needs, so a policy computes only those branches.

Rules (:data:`COORDINATIONS`):

- ``"workflow"`` (paper, Section III-C): target occluded -> move; else grasp when the best
  grasp Q is at least Q*_g; else push. Without a Q*_g (``q_star`` ``None``) the grasp/push choice
  is the larger of the best grasp Q and the best push Q.
- ``"grasp_first"``: the workflow, but the grasp is asked first: a grasp whose best Q is at
  least Q*_g is taken even when the target is occluded (a partly covered target the grasp
  net already scores graspable needs no move); otherwise occluded -> move, else push. Not
  the paper's rule; measured against it on the Experiments page of the documentation. Without a Q*_g it is the workflow.
- ``"grasp_first_uncover_max_q"``: ``"grasp_first"``, but while the target is occluded and the
  grasp is not taken, the larger of the best move Q and the best push Q (as
  ``"uncover_max_q"``). For nets trained with ``uncover_max_q`` whose grasp net has learnt
  covered targets (``TrainingStage.covered_grasp_trials``). Not the paper's rule.
- ``"uncover_max_q"``: the workflow, but while the target is occluded the larger of the best
  move Q and the best push Q (either may uncover it). Not the paper's rule; meant for nets
  whose push is paid for uncovering as the move is (``RewardConfig.push_uncovers``), so the
  two values share a scale.
- ``"max_q"``: the primitive with the largest best Q (the paper's "w/o alternating training"
  ablation).

``available`` is what both the env allows and the network has: a grasp-only net on an env
that allows all three always grasps (the paper's Grasping-Only baseline); a push+grasp net
decides between push and grasp by its own rule, without move.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from mpg_envs.grid.actions import check_primitives
from mpg_envs.grid.primitive_specs import GRASP, MOVE, PUSH

COORDINATIONS: tuple[str, ...] = ("workflow", "grasp_first", "uncover_max_q", "grasp_first_uncover_max_q", "max_q")
"""Ways to pick the primitive: the paper's workflow, the workflow asking the grasp first, the
workflow uncovering by the larger of move and push Q, both of those, or the plain max over the
Q maps."""


def check_coordination(rule: str) -> str:
    """``rule`` if it is one of :data:`COORDINATIONS`; else ``ValueError`` naming the valid ones."""
    if rule not in COORDINATIONS:
        raise ValueError(f"coordination must be one of {COORDINATIONS}, got {rule!r}")
    return rule


def usable_primitives(env_primitives: Sequence[str], net_primitives: Sequence[str]) -> tuple[str, ...]:
    """The primitives a policy can use: those the env allows and the network has a branch for.

    Raises ``ValueError`` when there are none (the network cannot act on this env at all).
    """
    env_p, net_p = check_primitives(env_primitives), check_primitives(net_primitives)
    usable = tuple(p for p in env_p if p in net_p)
    if not usable:
        raise ValueError(f"the network's branches {net_p} include none of the primitives {env_p} this env allows")
    return usable


def choose_primitive(
    rule: str,
    available: Sequence[str],
    occluded: bool,
    q_star: float | None,
    best_q: Callable[[str], float],
) -> str:
    """The primitive to use now.

    Args:
        rule: one of :data:`COORDINATIONS`.
        available: usable primitives in canonical order (see :func:`usable_primitives`).
        occluded: the observation's occlusion bit.
        q_star: Q*_g; ``None``: none yet (compare the best grasp and push Q instead).
        best_q: ``primitive -> best Q`` (called only for the primitives the rule compares).

    Raises:
        ValueError: an unknown rule, or a NaN ``q_star`` (``None`` says "no Q*_g").
    """
    check_coordination(rule)
    if q_star is not None and math.isnan(q_star):
        raise ValueError("q_star must be a number, or None for no Q*_g yet; got NaN")
    available = check_primitives(available)
    if len(available) == 1:
        return available[0]
    if rule == "max_q":
        return _largest(available, best_q)
    if rule in ("grasp_first", "grasp_first_uncover_max_q") and occluded and GRASP in available and q_star is not None:
        if best_q(GRASP) >= q_star:
            return GRASP
    if MOVE in available and occluded:
        if rule in ("uncover_max_q", "grasp_first_uncover_max_q") and PUSH in available:
            return _largest((MOVE, PUSH), best_q)
        return MOVE
    if GRASP in available and PUSH in available:
        if q_star is None:
            return _largest((GRASP, PUSH), best_q)
        return GRASP if best_q(GRASP) >= q_star else PUSH
    # Not occluded and only one of grasp/push usable besides move (e.g. a move+grasp net).
    return next(p for p in available if p != MOVE)


def _largest(candidates: Sequence[str], best_q: Callable[[str], float]) -> str:
    """The first candidate with the largest best Q (ties keep the earlier one)."""
    values = [(best_q(p), p) for p in candidates]
    best = values[0]
    for value in values[1:]:
        if value[0] > best[0]:
            best = value
    return best[1]
