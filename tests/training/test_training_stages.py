"""The training stages as data (mpg_agents.learning.training_stages) and the ablations and baselines as
table changes (mpg_agents.learning.stage_variants)."""

from __future__ import annotations

import pytest

from mpg_agents.learning.stage_variants import BASELINES, at_budget, without_alternation, without_multistage
from mpg_agents.learning.training_stages import (
    TRAINING_STAGES,
    TrainingStage,
    select_stages,
    stage_for_env,
    with_overrides,
)
from mpg_envs.tasks.rewards import RewardConfig


def test_the_paper_table():
    by = {s.name: s for s in TRAINING_STAGES}
    assert [s.name for s in TRAINING_STAGES] == ["Stage1", "Stage2", "Stage3", "Stage4", "Stage5"]
    assert by["Stage2"].calibrates_q_star and not any(s.calibrates_q_star for s in TRAINING_STAGES if s.name != "Stage2")
    assert [s.name for s in TRAINING_STAGES if s.uses_discriminator] == ["Stage3", "Stage4", "Stage5"]
    assert by["Stage3"].objects == (2, 4) and by["Stage4"].push_budget == 5 and by["Stage4"].trainable == ("push",)
    assert by["Stage5"].alternate_every > 0 and by["Stage5"].coordination == "workflow"


def test_curriculum_grows_linearly():
    stage = TrainingStage("s", "MPG-Stage3-v0", objects=(2, 4))
    assert [stage.objects_at(f) for f in (0.0, 0.2, 0.5, 1.0, 3.0)] == [2, 2, 3, 4, 4]
    assert TrainingStage("s", "MPG-Stage2-v0").objects_at(0.5) is None


def test_ablations_are_table_changes():
    assert without_multistage(TRAINING_STAGES) == (TRAINING_STAGES[-1],)
    ablated = without_alternation(TRAINING_STAGES)
    assert ablated[-1].alternate_every == 0 and ablated[-1].coordination == "max_q"
    assert ablated[:-1] == TRAINING_STAGES[:-1]


def test_lookup_selection_and_overrides():
    assert stage_for_env("MPG-Stage4-v0").push_budget == 5
    other = stage_for_env("MPG-Occluded-v0")
    assert other.trainable is None and other.push_budget is None and not other.uses_discriminator
    assert [s.name for s in select_stages(TRAINING_STAGES, ["1", "Stage2"])] == ["Stage1", "Stage2"]
    with pytest.raises(ValueError, match="unknown stage"):
        select_stages(TRAINING_STAGES, ["9"])
    changed = with_overrides(TRAINING_STAGES, {"Stage3": {"objects": [2, 3], "iterations": 7}})
    assert changed[2].objects == (2, 3) and changed[2].iterations == 7
    # A config that moves Stage V to the hard track: its old env id is refused, naming the new one.
    moved = with_overrides(TRAINING_STAGES, {"Stage5": {"env_id": "MPG-OccludedHard-v0"}})
    assert stage_for_env("MPG-OccludedHard-v0", moved) is moved[-1]
    with pytest.raises(ValueError, match="moves Stage5 to MPG-OccludedHard-v0; give --env MPG-OccludedHard-v0"):
        stage_for_env("MPG-Stage5-v0", moved)
    with pytest.raises(ValueError, match="training stage settings has unknown TrainingStage fields"):
        with_overrides(TRAINING_STAGES, {"Stage3": {"objetcs": [2, 3]}})
    with pytest.raises(ValueError, match="coordination"):
        TrainingStage("s", "MPG-Stage5-v0", coordination="vote")


def test_branch_init_pairs_are_checked_and_round_trip():
    stage = TrainingStage("s", "MPG-Stage3-v0", branch_init=[["move", "grasp"]])
    assert stage.branch_init == (("move", "grasp"),)
    assert TrainingStage.from_dict(stage.to_dict()) == stage
    changed = with_overrides(TRAINING_STAGES, {"Stage3": {"branch_init": [["move", "grasp"]]}})
    assert changed[2].branch_init == (("move", "grasp"),) and TRAINING_STAGES[2].branch_init == ()
    for bad in ([["move", "move"]], [["move", "lift"]], [["move"]]):
        with pytest.raises(ValueError):
            TrainingStage("s", "MPG-Stage3-v0", branch_init=bad)


def test_learned_baselines_are_table_changes_at_the_same_budget():
    total = sum(s.iterations for s in TRAINING_STAGES)
    for name, make in BASELINES.items():
        table = make(TRAINING_STAGES)
        assert sum(s.iterations for s in table) == total, name
        assert "move" not in (table[-1].branches or ()) and table[-1].env_id == TRAINING_STAGES[-1].env_id
        assert all(s.uses_discriminator or s.trainable == ("grasp",) for s in table)
    grasp_only = BASELINES["grasp-only"](TRAINING_STAGES)
    assert [s.name for s in grasp_only] == ["Stage1", "Stage2", "Stage5"] and grasp_only[-1].branches == ("grasp",)
    calibrated = with_overrides(TRAINING_STAGES, {"Stage5": {"calibration_episodes": 50, "calibrate_every": 300}})
    grasping = BASELINES["grasp-only"](calibrated)[-1]
    assert (grasping.calibration_episodes, grasping.calibrate_every) == (0, 0)
    assert BASELINES["push-grasp"](calibrated)[-1].calibration_episodes == 50  # its Q*_g rule uses it
    # By the larger Q nothing reads Q*_g: neither to-vpg nor the ablation calibrates it.
    by_larger_q = BASELINES["to-vpg"](calibrated)[-1]
    assert (by_larger_q.calibration_episodes, by_larger_q.calibrate_every) == (0, 0)
    assert without_alternation(calibrated)[-1].calibration_episodes == 0
    assert without_multistage(calibrated)[-1].calibration_episodes == 50
    assert calibrated[-1].reads_q_star and not grasping.reads_q_star
    vpg = BASELINES["to-vpg"](TRAINING_STAGES)
    assert vpg[-1].coordination == "max_q" and vpg[-1].alternate_every == 0 and vpg[-1].trainable == ("push", "grasp")
    epg = BASELINES["push-grasp"](TRAINING_STAGES)
    assert [s.name for s in epg] == ["Stage1", "Stage2", "Stage4", "Stage5"]
    assert epg[-1].coordination == "workflow" and epg[-1].alternate_every > 0
    # MPGNet's move-versus-push options stay MPGNet's: a baseline without a move trains its pushes
    # under the paper's reward and tries no rival actions; other reward options are kept.
    one_scale = with_overrides(
        TRAINING_STAGES, {"Stage5": {"rival_trials": True, "coordination": "uncover_max_q", "reward": {"push_uncovers": True, "move_needs_lift": True}}}
    )
    for name, make in BASELINES.items():
        last = make(one_scale)[-1]
        assert not last.rival_trials and last.reward == (("move_needs_lift", True),), name
        assert last.coordination == ("max_q" if name == "to-vpg" else "workflow"), name
    assert without_multistage(one_scale)[-1].rival_trials and without_multistage(one_scale)[-1].reward == one_scale[-1].reward
    grasping_first = with_overrides(TRAINING_STAGES, {"Stage5": {"coordination": "grasp_first_uncover_max_q"}})
    assert BASELINES["push-grasp"](grasping_first)[-1].coordination == "grasp_first"
    with pytest.raises(ValueError, match="budget"):
        at_budget(TRAINING_STAGES, 10)
    with pytest.raises(ValueError, match="branches"):
        TrainingStage("s", "MPG-Stage5-v0", trainable=("move",), branches=("push", "grasp"))


def test_calibration_episodes_are_checked():
    stage = TrainingStage("S", "MPG-Stage5-v0", calibration_episodes=50)
    assert TrainingStage.from_dict(stage.to_dict()) == stage
    with pytest.raises(ValueError, match="calibration_episodes must be >= 0"):
        TrainingStage("S", "MPG-Stage5-v0", calibration_episodes=-1)
    with pytest.raises(ValueError, match="choose one"):
        TrainingStage("S", "MPG-Stage2-v0", calibrates_q_star=True, calibration_episodes=5)
    with pytest.raises(ValueError, match=r"calibration_quantile must be in \[0, 1\]"):
        TrainingStage("S", "MPG-Stage5-v0", calibration_episodes=5, calibration_quantile=1.5)
    with pytest.raises(ValueError, match="calibrate_every must be 0, or >= 1 with calibration_episodes"):
        TrainingStage("S", "MPG-Stage5-v0", calibrate_every=300)


def test_unequal_alternation_and_finish_choose_the_learning_branches():
    nets = ("move", "push", "grasp")
    equal = TrainingStage("s", "MPG-Stage5-v0", trainable=nets, alternate_every=50, iterations=1500)
    assert [equal.branches_at(i, 1500, nets)[0] for i in (0, 50, 100, 150, 149)] == ["move", "push", "grasp", "move", "grasp"]
    shared = with_overrides((equal,), {"s": {"alternate_shares": [["grasp", 3]]}})[0]
    assert shared.alternate_shares == (("grasp", 3),) and TrainingStage.from_dict(shared.to_dict()) == shared
    # A round of 250 iterations: move 50, push 50, grasp 150.
    turns = [shared.branches_at(i, 1500, nets)[0] for i in range(0, 500, 50)]
    assert turns == ["move", "push", "grasp", "grasp", "grasp"] * 2
    assert sum(shared.branches_at(i, 1500, nets) == ("grasp",) for i in range(1500)) == 900
    finish = TrainingStage("s", "MPG-Stage5-v0", trainable=nets, alternate_every=50, iterations=2100,
                           finish_iterations=600, finish_trainable=["grasp"])
    assert finish.branches_at(1400, 2100, nets) == ("push",)
    assert all(finish.branches_at(i, 2100, nets) == ("grasp",) for i in range(1500, 2100))
    assert finish.branches_at(1400, 1700, nets) == ("grasp",)  # --steps shortens the stage, the finish stays at its end
    assert TrainingStage("s", "MPG-Stage5-v0", iterations=9).branches_at(3, 9, nets) == nets
    # The ablation without alternation trains every net at once to the end.
    ablated = without_alternation((finish,))[0]
    assert ablated.finish_iterations == 0 and ablated.branches_at(2000, 2100, nets) == nets


def test_a_stage_sets_reward_fields():
    stage = with_overrides((TrainingStage("s", "MPG-Stage3-v0"),), {"s": {"reward": {"move_needs_lift": True}}})[0]
    assert stage.reward == (("move_needs_lift", True),) and stage.reward_config().move_needs_lift
    assert TrainingStage.from_dict(stage.to_dict()) == stage and stage.to_dict()["reward"] == {"move_needs_lift": True}
    assert TrainingStage("s", "MPG-Stage3-v0").reward_config() == RewardConfig()


def test_trials_round_trip_and_default_off():
    stage = with_overrides((TrainingStage("s", "MPG-Occluded-v0"),), {"s": {"grasp_trials": 3, "move_trials": 2}})[0]
    assert (stage.grasp_trials, stage.move_trials) == (3, 2) and TrainingStage.from_dict(stage.to_dict()) == stage
    assert all(s.grasp_trials == s.move_trials == 0 for s in TRAINING_STAGES)  # the paper's pipeline is pure RL


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"reward": {"move_needs_lfit": True}}, "reward takes RewardConfig fields"),
        ({"grasp_trials": 8}, r"grasp_trials must be an integer in 0\.\.7"),
        ({"grasp_trials": -1}, "grasp_trials"),
        ({"grasp_trials": 2.0}, "grasp_trials"),
        ({"move_trials": 9}, r"move_trials must be an integer in 0\.\.8"),
        ({"move_trials": True}, "move_trials"),
        ({"alternate_shares": [["grasp", 0]]}, "turns; need >= 1"),
        ({"alternate_shares": [["lift", 2]]}, "lift"),
        ({"finish_iterations": 600}, "go together"),
        ({"finish_trainable": ["grasp"]}, "go together"),
        ({"finish_iterations": 1000, "finish_trainable": ["grasp"]}, r"finish_iterations must be in \[0, iterations=1000\)"),
        ({"finish_iterations": 10, "finish_trainable": ["move"], "branches": ["push", "grasp"]}, "not among its branches"),
    ],
)
def test_alternation_shares_and_finish_are_checked(fields, message):
    with pytest.raises(ValueError, match=message):
        TrainingStage("s", "MPG-Stage5-v0", iterations=1000, **fields)
