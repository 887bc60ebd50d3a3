"""The paper's ablations and learned baselines as changes of the stage table
(:data:`~mpg_agents.learning.training_stages.TRAINING_STAGES`).

The ablations: without multi-stage training (:func:`without_multistage`) and
without alternating training (:func:`without_alternation`). The learned baselines of Table I
(:data:`BASELINES`) train fewer nets at MPGNet's budget (:func:`at_budget`), without MPGNet's
move-versus-push options (:data:`MOVE_VERSUS_PUSH`, :data:`WITHOUT_MOVE_VERSUS_PUSH`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

from mpg_agents.learning.training_stages import TrainingStage
from mpg_envs.grid.primitive_specs import GRASP, PUSH


def without_multistage(stages: Sequence[TrainingStage]) -> tuple[TrainingStage, ...]:
    """Ablation "w/o multi-stage training": only the last (joint) stage, from scratch."""
    return (stages[-1],)


def without_alternation(stages: Sequence[TrainingStage]) -> tuple[TrainingStage, ...]:
    """Ablation "w/o alternating training": stages that alternate (or finish with some nets
    alone) train all their nets at once and choose actions by the largest Q."""
    return tuple(
        _without_unused_calibration(
            replace(s, alternate_every=0, alternate_shares=(), finish_iterations=0, finish_trainable=(), coordination="max_q")
        )
        if s.alternate_every or s.finish_iterations
        else s
        for s in stages
    )


def _without_unused_calibration(stage: TrainingStage) -> TrainingStage:
    """``stage`` without in-scene Q*_g calibrations when its coordination never reads Q*_g:
    each costs 50 episodes (about a minute and a half on 2 cores) for a value nothing uses."""
    if stage.reads_q_star or not stage.calibration_episodes:
        return stage
    return replace(stage, calibration_episodes=0, calibrate_every=0)


def at_budget(stages: Sequence[TrainingStage], iterations: int) -> tuple[TrainingStage, ...]:
    """``stages`` with the last one's iterations set so that all together do ``iterations``."""
    before = sum(s.iterations for s in stages[:-1])
    if iterations <= before:
        raise ValueError(f"a budget of {iterations} iterations leaves none for {stages[-1].name} (the others take {before})")
    return (*stages[:-1], replace(stages[-1], iterations=iterations - before))


MOVE_VERSUS_PUSH = ("push_uncovers",)
"""Reward options that value a push against the move it replaces: MPGNet's, so the learned
baselines (which have no move) train without them, under the paper's push reward (and without
rival trials; ``uncover_max_q``, which only differs from the workflow for a net with a move,
becomes the workflow)."""

WITHOUT_MOVE_VERSUS_PUSH = {"uncover_max_q": "workflow", "grasp_first_uncover_max_q": "grasp_first"}
"""The rule a learned baseline trains with in place of MPGNet's move-versus-push rules."""


def _learned_baseline(
    stages: Sequence[TrainingStage], keep: Sequence[tuple[str, ...]], **last: Any
) -> tuple[TrainingStage, ...]:
    """The earlier stages that train only ``keep``'s branch sets, then the last stage changed by
    ``last`` (no branch initialisation, no rival trials, no move-versus-push reward), with the
    whole budget of ``stages``."""
    kept = tuple(s for s in stages[:-1] if s.trainable in keep)
    last_stage = stages[-1]
    changes: dict[str, Any] = {
        "branch_init": (),
        "rival_trials": False,
        "reward": tuple(pair for pair in last_stage.reward if pair[0] not in MOVE_VERSUS_PUSH),
        "coordination": WITHOUT_MOVE_VERSUS_PUSH.get(last_stage.coordination, last_stage.coordination),
        **last,
    }
    final = _without_unused_calibration(replace(last_stage, **changes))
    return at_budget((*kept, final), sum(s.iterations for s in stages))


def grasp_only_baseline(stages: Sequence[TrainingStage]) -> tuple[TrainingStage, ...]:
    """Baseline "Grasping-Only": the grasp stages, then grasping alone in the joint stage's clutter
    (no Q*_g calibration there: a net with one primitive never consults Q*_g)."""
    return _learned_baseline(stages, [(GRASP,)], trainable=(GRASP,), branches=(GRASP,), alternate_every=0)


def target_vpg_baseline(stages: Sequence[TrainingStage]) -> tuple[TrainingStage, ...]:
    """Baseline "Target-Oriented VPG": after the grasp stages, push and grasp nets trained
    together in the joint stage's clutter, the action by the larger Q (no move, no Q*_g rule,
    so no Q*_g calibration there)."""
    return _learned_baseline(
        stages, [(GRASP,)], trainable=(PUSH, GRASP), branches=(PUSH, GRASP), alternate_every=0, coordination="max_q"
    )


def push_grasp_baseline(stages: Sequence[TrainingStage]) -> tuple[TrainingStage, ...]:
    """Baseline "Efficient Push-Grasping" style: the grasp stages and Q*_g, the push stage, then
    push and grasp trained in turn in the joint stage's clutter, grasping when grasp Q >= Q*_g (no move)."""
    return _learned_baseline(stages, [(GRASP,), (PUSH,)], trainable=(PUSH, GRASP), branches=(PUSH, GRASP))


BASELINES: dict[str, Callable[[Sequence[TrainingStage]], tuple[TrainingStage, ...]]] = {
    "grasp-only": grasp_only_baseline,
    "to-vpg": target_vpg_baseline,
    "push-grasp": push_grasp_baseline,
}
"""The learned baselines of Table I, each a change of the stage table at MPGNet's budget."""
