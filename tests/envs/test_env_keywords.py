"""The checks of the env's keywords (``mpg_envs.tasks.env_keywords``) and the step's judgement
(``mpg_envs.tasks.step_evaluation.judge_step``), by hand, without a simulator."""

import numpy as np
import pytest

from mpg_envs.perception.occlusion import ChangeConfig
from mpg_envs.scenes.scene_io import MAX_OBJECTS
from mpg_envs.simulation.primitives import PrimitiveResult
from mpg_envs.tasks.env_keywords import (
    check_grasp_scorer,
    check_max_motions,
    check_num_objects,
    check_obs_mode,
    check_render_mode,
    check_use_test_set,
    check_visible_range,
    check_wrong_grasp,
    stage_of,
)
from mpg_envs.tasks.stages import STAGES
from mpg_envs.tasks.step_evaluation import judge_step

HARD, STAGE1, STAGE3 = STAGES["OccludedHard"], STAGES["Stage1"], STAGES["Stage3"]


def test_a_stage_is_a_name_or_a_spec():
    assert stage_of("Stage3") is STAGE3 and stage_of(STAGE3) is STAGE3
    with pytest.raises(ValueError, match=r"unknown stage 'Stage9'; valid: \['Occluded'"):
        stage_of("Stage9")


def test_object_counts_are_integers_in_the_stages_range():
    assert check_num_objects(np.int64(2), STAGE3) == 2 and type(check_num_objects(np.int64(2), STAGE3)) is int
    for bad in (1, MAX_OBJECTS + 1, True, 2.0, None):
        with pytest.raises(ValueError, match=rf"num_objects must be an integer in 2\.\.{MAX_OBJECTS} for MPG-Stage3-v0, got"):
            check_num_objects(bad, STAGE3)


def test_none_takes_the_stages_rule_and_band():
    assert check_wrong_grasp(None, HARD) == "fail" and check_wrong_grasp("remove", HARD) == "remove"
    assert check_visible_range(None, HARD) == (0.0, 0.3) and check_visible_range(None, STAGE3) is None
    assert check_visible_range((0.2, 0.5), STAGE3) == (0.2, 0.5)
    assert check_max_motions(None, STAGE3) == 5 and check_max_motions(np.int32(3), STAGE3) == 3
    with pytest.raises(ValueError, match=r"wrong_grasp must be one of \('remove', 'fail'\), got 'drop'"):
        check_wrong_grasp("drop", HARD)
    with pytest.raises(ValueError, match="wrong_grasp='fail' needs a target; MPG-Stage1-v0 has none"):
        check_wrong_grasp("fail", STAGE1)
    with pytest.raises(ValueError, match="visible_range needs a target; MPG-Stage1-v0 has none"):
        check_visible_range((0.0, 0.5), STAGE1)
    for bad in (0, -1, 2.5, "3"):
        with pytest.raises(ValueError, match=f"max_motions must be a positive integer, got {bad!r}"):
            check_max_motions(bad, STAGE3)


def test_flags_modes_and_the_scorer():
    assert check_use_test_set(np.bool_(False)) is False
    with pytest.raises(ValueError, match="use_test_set must be True or False, got 1"):
        check_use_test_set(1)
    assert check_obs_mode("camera") == "camera"
    with pytest.raises(ValueError, match=r"obs_mode must be one of \('raycast', 'camera'\), got 'rgb'"):
        check_obs_mode("rgb")
    assert check_render_mode(None, ["rgb_array"]) is None and check_render_mode("rgb_array", ["rgb_array"]) == "rgb_array"
    with pytest.raises(ValueError, match=r"render_mode must be None or one of \['rgb_array'\], got 'human'"):
        check_render_mode("human", ["rgb_array"])
    assert check_grasp_scorer(None) is None and check_grasp_scorer(len) is len
    with pytest.raises(ValueError, match="grasp_scorer must be a callable obs -> float"):
        check_grasp_scorer(0.5)


class TwoObjects:
    """What the judgement reads of a world: object 1 (the target) left the workspace when ``out``."""

    def __init__(self, out: bool = False, left: int = 2):
        self.active, self.out, self.left = np.array([True, True]), out, left

    def objects_outside_workspace(self) -> np.ndarray:
        return np.array([1] if self.out else [], dtype=int)

    def objects_left(self) -> int:
        return self.left


def obs(occluded: bool, height: float = 0.0) -> dict[str, np.ndarray]:
    depth = np.full((20, 20), height, np.float32)
    return {"depth": depth, "mask": np.zeros((20, 20), np.uint8), "occluded": np.array([int(occluded)])}


def judge(primitive, before, after, result, world, **kw):
    settings = dict(mask_all_objects=False, mis_pick_rule="fail", change=ChangeConfig(), grasp_gain=0.0)
    settings.update(visible_before=kw.pop("visible_before", 0.2), visible=kw.pop("visible", 0.7))
    return judge_step(primitive, before, after, result, world, 1, **{**settings, **kw})


def test_a_move_that_uncovers_the_target_succeeds_as_a_move():
    result = PrimitiveResult("move", 0, (3, 3), (0.5, 0.0, 0.05), lifted=True, grasped_object=0)
    e = judge("move", obs(True), obs(False), result, TwoObjects(), grasp_gain=0.25)
    o = e.outcome
    assert o.move_success and o.cleared and o.covered_before and o.change_detected  # lifted: changed
    assert not o.target_grasped and not e.mis_pick and not e.is_success and not e.ends_wrong_object
    assert o.visible_gain == pytest.approx(0.5) and o.grasp_q_gain == 0.25
    assert (e.occluded_before, e.occluded, e.visible_fraction, e.objects_left) == (True, False, 0.7, 2)


def test_grasps_of_the_target_and_of_another_object():
    right = PrimitiveResult("grasp", 0, (3, 3), (0.5, 0.0, 0.05), lifted=True, grasped_object=1)
    e = judge("grasp", obs(True), obs(True), right, TwoObjects(left=1), visible=None)
    assert e.is_success and e.outcome.target_grasped and not e.mis_pick
    assert e.outcome.visible_gain == 0.0  # no visible fraction after: no gain
    wrong = PrimitiveResult("grasp", 0, (3, 3), (0.5, 0.0, 0.05), lifted=True, grasped_object=0)
    e = judge("grasp", obs(True), obs(True), wrong, TwoObjects(left=1))
    assert e.mis_pick and e.wrong_grasp and e.ends_wrong_object  # wrong_grasp: the former name and not e.is_success
    assert not judge("grasp", obs(True), obs(True), wrong, TwoObjects(), mis_pick_rule="remove").ends_wrong_object
    e = judge("grasp", obs(True), obs(True), wrong, TwoObjects(left=0), mask_all_objects=True)
    assert e.is_success and e.outcome.target_grasped and not e.mis_pick  # Stage I: every object, table empty


def test_a_push_that_drives_the_target_out_clears_nothing():
    result = PrimitiveResult("push", 0, (3, 3), (0.5, 0.0, 0.02))
    e = judge("push", obs(True), obs(False, 0.02), result, TwoObjects(out=True))
    assert e.target_out and not e.outcome.cleared and not e.outcome.move_success
    assert e.outcome.change_detected  # 400 pixels rose 2 cm: more than 300 changed
    assert not judge("push", obs(True), obs(True), result, TwoObjects()).outcome.change_detected
