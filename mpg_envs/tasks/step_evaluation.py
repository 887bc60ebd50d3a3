"""What one step did, as data: the env's ``evaluate`` hook fills a :class:`StepEvaluation`
(:func:`judge_step`); the reward, the episode's end and the step's ``info`` are read off it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mpg_envs.grid.primitive_specs import MOVE, primitive_spec
from mpg_envs.perception.occlusion import ChangeConfig, change_detected
from mpg_envs.simulation.primitives import PrimitiveResult
from mpg_envs.simulation.world import World
from mpg_envs.tasks.rewards import StepOutcome


def action_info(primitive: str, rotation: int, row: int, col: int, result: PrimitiveResult) -> dict[str, Any]:
    """The step-``info`` entries that say what was done and how the motion went."""
    return {
        "primitive": primitive,
        "rotation": int(rotation),
        "pixel": (int(row), int(col)),
        "position": tuple(float(v) for v in result.position),
        "grasp_failure": result.grasp_failure,  # why a grasp or move held nothing (GRASP_FAILURES), else None
        "unreachable": bool(result.unreachable),  # the arm could not reach the pose: nothing moved
        "physics_steps": int(result.physics_steps),
    }


@dataclass(frozen=True)
class StepEvaluation:
    """The judged outcome of one step.

    Attributes:
        outcome: the facts the paper's rewards need (:class:`~mpg_envs.tasks.rewards.StepOutcome`).
        mis_pick: a grasp lifted an object other than the target (the event; ``info["wrong_grasp"]``,
            and ``wrong_grasp``, its former name here).
        ends_wrong_object: ... and the env's mis-pick rule (its keyword ``wrong_grasp="fail"``,
            strict retrieval) ends the episode for it.
        is_success: the task is done (the target grasped; Stage I: the table empty).
        target_out: the target left the workspace.
        occluded_before: the target was occluded before the step (the paper's flag).
        occluded: ... and after it.
        visible_fraction: share of the target's footprint where the target is the top
            surface after the step (``None`` without a target in view).
        objects_left: objects still in the scene and inside the workspace.
    """

    outcome: StepOutcome
    mis_pick: bool
    ends_wrong_object: bool
    is_success: bool
    target_out: bool
    occluded_before: bool
    occluded: bool
    visible_fraction: float | None
    objects_left: int

    @property
    def wrong_grasp(self) -> bool:
        """The former name of :attr:`mis_pick` (kept)."""
        return self.mis_pick

    def info(self) -> dict[str, Any]:
        """The step-``info`` entries this evaluation owns (a fresh dict)."""
        o = self.outcome
        return {
            "lifted": bool(o.lifted),
            "grasp_success": bool(o.lifted),  # the spec's name of "lifted" (kept: users read it)
            "target_grasped": bool(o.target_grasped),
            "wrong_grasp": bool(self.mis_pick),  # the event's name users read
            "change_detected": bool(o.change_detected),
            "occluded_before": self.occluded_before,
            "occluded": self.occluded,
            "visible_fraction": self.visible_fraction,
            "move_success": bool(o.move_success),
            "is_success": bool(self.is_success),
            "objects_left": int(self.objects_left),
            "target_out_of_workspace": bool(self.target_out),
            "grasp_q_gain": float(o.grasp_q_gain),
            "visible_gain": float(o.visible_gain),
        }


def judge_step(
    primitive: str,
    before: dict[str, np.ndarray],
    obs: dict[str, np.ndarray],
    result: PrimitiveResult,
    world: World,
    target: int | None,
    *,
    mask_all_objects: bool,
    mis_pick_rule: str,
    change: ChangeConfig,
    grasp_gain: float,
    visible_before: float | None,
    visible: float | None,
) -> StepEvaluation:
    """What the step did, judged on the new state ``obs`` of ``world`` against the observation
    ``before`` it: success (the target grasped; with ``mask_all_objects`` the table empty),
    mis-pick (with ``mis_pick_rule="fail"``, the env's ``wrong_grasp="fail"``, it ends the
    episode), move success (a move that left the target uncovered), occlusion, the visible
    fraction ``visible`` and its gain over ``visible_before``, change (``change``'s test);
    ``grasp_gain``: the grasp scorer's gain."""
    target_grasped = bool(result.lifted and (mask_all_objects or result.grasped_object == target))
    target_out = (
        target is not None and bool(world.active[target]) and target in set(world.objects_outside_workspace().tolist())
    )
    occluded_before = bool(before["occluded"][0])
    occluded = bool(obs["occluded"][0])
    changed = change_detected(before["depth"], obs["depth"], before["mask"], result.lifted, change)
    cleared = occluded_before and not occluded and not target_grasped and not target_out
    move_success = primitive == MOVE and cleared
    retrieves = primitive_spec(primitive).retrieves  # what it lifts leaves the scene: a grasp
    mis_pick = bool(retrieves and result.lifted and not target_grasped)
    is_success = world.objects_left() == 0 if mask_all_objects else bool(target_grasped and retrieves)
    seen = 0.0 if visible is None or visible_before is None else visible - visible_before
    return StepEvaluation(
        outcome=StepOutcome(
            primitive,
            result.lifted,
            target_grasped,
            move_success,
            changed,
            grasp_gain,
            seen,
            covered_before=occluded_before,
            cleared=cleared,
        ),
        mis_pick=mis_pick,
        ends_wrong_object=mis_pick and mis_pick_rule == "fail",
        is_success=is_success,
        target_out=bool(target_out),
        occluded_before=occluded_before,
        occluded=occluded,
        visible_fraction=visible,
        objects_left=world.objects_left(),
    )
