"""The training stages and the test scene as data: one :class:`StageSpec` per registered env."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from mpg_envs.grid.primitive_specs import GRASP, MOVE, PUSH
from mpg_envs.tasks.rewards import (
    RewardConfig,
    StepOutcome,
    reward_grasp_any,
    reward_grasp_target,
    reward_move,
    reward_per_primitive,
)

RewardFn = Callable[[StepOutcome, RewardConfig], float]

WRONG_GRASP_RULES = ("remove", "fail")
"""What a grasp that lifts a non-target object does: ``remove`` (the paper's protocol: the
object leaves the scene and the episode goes on) or ``fail`` (strict retrieval: the episode
ends as a failure, ``end_reason="wrong_object"``)."""

HARD_VISIBLE_MAX = 0.3
"""The hard track's bound: its target is at most this fraction visible at reset (``OccludedHard``
and every track built on it); its test scenes were drawn with it."""

END_REASONS = (
    "target_grasped",
    "table_empty",
    "move_success",
    "target_left_workspace",
    "grasp_done",
    "wrong_object",
    "motion_cap",
)
"""Values of ``info["end_reason"]`` on the last step of an episode (``None`` before it):

- ``target_grasped``: the target was grasped (success; Stages 2-5 and Occluded).
- ``table_empty``: no object is left in the workspace (Stage 1's success).
- ``move_success``: a move uncovered the target (Stage 3's success).
- ``target_left_workspace``: the target was pushed or knocked out of the workspace.
- ``grasp_done``: Stage 4's one grasp was made and did not take the target.
- ``wrong_object``: strict retrieval (``wrong_grasp="fail"``): a grasp lifted an object
  other than the target (a failure).
- ``motion_cap``: ``max_motions`` motions were used up (truncated).
"""


@dataclass(frozen=True)
class StageSpec:
    """Everything that makes one env differ from another."""

    name: str
    primitives: tuple[str, ...]
    generator: str  # key of mpg_envs.scenes.generators.GENERATORS: how a reset drops its objects
    num_objects: int
    max_motions: int  # truncation cap
    reward: RewardFn
    mask_all_objects: bool = False  # Stage I: the mask shows every object, "grasp anything"
    start_occluded: bool | None = None  # required initial occlusion of the target (None: any)
    start_surrounded: int = 0  # required sectors (of 8) around the target with a neighbour close by
    end_on_move_success: bool = False  # Stage III ends once a move uncovers the target
    end_after_grasp: bool = False  # Stage IV: pushes, then one grasp ends the episode
    min_objects: int = 1
    wrong_grasp: str = "remove"  # one of WRONG_GRASP_RULES (the env's default)
    visible_range: tuple[float, float] | None = None  # band of the target's visible fraction at reset
    test_set: str | None = None  # name of the shipped scene sets of its test seeds (mpg_envs.scenes.test_sets)

    @property
    def env_id(self) -> str:
        return f"MPG-{self.name}-v0"


STAGES: dict[str, StageSpec] = {
    s.name: s
    for s in (
        StageSpec("Stage1", (GRASP,), "scattered", 5, 15, reward_grasp_any, mask_all_objects=True),
        StageSpec("Stage2", (GRASP,), "isolated_target", 5, 10, reward_grasp_target),
        StageSpec(
            "Stage3",
            (MOVE,),
            "occluded_target",
            2,
            5,
            reward_move,
            start_occluded=True,
            end_on_move_success=True,
            min_objects=2,
        ),
        StageSpec(
            "Stage4",
            (PUSH, GRASP),
            "surrounded_target",
            7,
            6,
            reward_per_primitive,
            start_occluded=False,
            start_surrounded=6,
            end_after_grasp=True,
            min_objects=2,
        ),
        StageSpec("Stage5", (MOVE, PUSH, GRASP), "clustered", 10, 10, reward_per_primitive),
        StageSpec(
            "Occluded",
            (MOVE, PUSH, GRASP),
            "test_cluster",
            15,
            10,
            reward_per_primitive,
            start_occluded=True,
            min_objects=5,
            test_set="occluded",
        ),
        StageSpec(
            "OccludedHard",
            (MOVE, PUSH, GRASP),
            "test_cluster",
            15,
            10,
            reward_per_primitive,
            start_occluded=True,
            min_objects=5,
            wrong_grasp="fail",
            visible_range=(0.0, HARD_VISIBLE_MAX),
            test_set="occluded_hard",
        ),
    )
}
"""Stage name -> spec. Stage IV allows 5 pushes and then a grasp (6 motions). OccludedHard:
the test scenes with the target at most 30% visible at reset, strict retrieval."""


def episode_end(
    stage: StageSpec,
    *,
    is_success: bool,
    target_out: bool,
    move_success: bool,
    primitive: str,
    num_motions: int,
    max_motions: int,
    wrong_object: bool = False,
) -> tuple[bool, bool, str | None]:
    """``(terminated, truncated, end_reason)`` after a step; ``end_reason`` is one of
    :data:`END_REASONS` on the last step and ``None`` before it. ``wrong_object``: a grasp
    lifted a non-target object under strict retrieval (a terminal failure)."""
    terminated = is_success or target_out or wrong_object or (stage.end_on_move_success and move_success)
    grasp_ends = stage.end_after_grasp and primitive == GRASP
    truncated = not terminated and (num_motions >= max_motions or grasp_ends)
    if is_success:
        reason: str | None = "table_empty" if stage.mask_all_objects else "target_grasped"
    elif target_out:
        reason = "target_left_workspace"
    elif wrong_object:
        reason = "wrong_object"
    elif terminated:
        reason = "move_success"
    elif truncated:
        reason = "grasp_done" if grasp_ends else "motion_cap"
    else:
        reason = None
    return terminated, truncated, reason
