"""A stage's env options: pooled training object sets, visual randomization, env config."""

from __future__ import annotations

import pytest

from mpg_agents.learning.actors import make_training_env
from mpg_agents.learning.train_config import TrainConfig
from mpg_agents.learning.training_objects import object_set_entries, stage_env_config, training_object_set
from mpg_agents.learning.training_stages import TRAINING_STAGES, TrainingStage, with_overrides
from mpg_envs.simulation.families import FAMILY_SET_SIZE


def test_object_set_entries_parse_names_and_training_seeds():
    assert object_set_entries("blocks") == [("blocks", None)]
    assert object_set_entries(["blocks", "procedural:3", "bent:499999"]) == [("blocks", None), ("procedural", 3), ("bent", 499999)]


@pytest.mark.parametrize(
    "value, message",
    [
        ("random_urdfs_test", "cannot be trained on"),  # the unseen-object track's test objects
        (["procedural:500000"], "training set's seed must be an integer in [0, 499999]"),  # a test seed
        (["procedural:700001"], "training set's seed"),  # a tuning seed
        (["procedural:x"], "training set's seed"),
        ([], "non-empty list"),
        (3, "set name or a non-empty list"),
        (["/some/folder"], "cannot be trained on"),
    ],
)
def test_object_set_entries_refuse_what_training_may_not_use(value, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        object_set_entries(value)


def test_a_plain_name_passes_through_and_a_list_is_pooled():
    assert training_object_set("procedural") == "procedural"
    pooled = training_object_set(["blocks", "superquadrics:1", "superquadrics:2"])
    blocks = training_object_set(["blocks:0"])
    assert len(pooled) == len(blocks) + 2 * FAMILY_SET_SIZE
    assert [a.source for a in pooled[len(blocks):]] == ["superquadrics"] * (2 * FAMILY_SET_SIZE)


def test_stage_env_options_are_checked_and_round_trip():
    options = {"object_set": ["blocks", "procedural:1"], "visual_randomization": True, "config": {"scene_tries": 50}}
    (stage,) = with_overrides(TRAINING_STAGES[:1], {"Stage1": {"env_options": options}})
    assert stage.env_options == (("config", {"scene_tries": 50}), ("object_set", ("blocks", "procedural:1")), ("visual_randomization", True))
    assert TrainingStage.from_dict(stage.to_dict()) == stage
    assert stage.to_dict()["env_options"]["object_set"] == ["blocks", "procedural:1"]
    for bad, message in (
        ({"num_objects": 3}, "env_options takes"),  # the stage's curriculum owns the count
        ({"obs_mode": "lidar"}, "obs_mode must be one of"),
        ({"visual_randomization": "on"}, "visual_randomization must be"),
        ({"config": {"reward": {}}}, "other than reward"),
        ({"config": {"scene_trys": 3}}, "unknown EnvConfig fields"),
    ):
        with pytest.raises(ValueError, match=message):
            with_overrides(TRAINING_STAGES[:1], {"Stage1": {"env_options": bad}})


def test_stage_env_config_puts_the_stage_reward_on_the_config_table():
    assert stage_env_config({}) is None
    config = stage_env_config({"config": {"scene_tries": 7}}, (("push_uncovers", True),))
    assert config.scene_tries == 7 and config.reward.push_uncovers is True
    assert stage_env_config({}, (("push_uncovers", True),)).scene_tries == stage_env_config({"config": {}}, (("push_uncovers", True),)).scene_tries


def test_the_training_env_draws_from_the_pooled_set_with_visual_randomization():
    options = {"object_set": ["blocks", "superquadrics:1"], "visual_randomization": True, "config": {"scene_tries": 30}}
    (stage,) = with_overrides(TRAINING_STAGES[1:2], {"Stage2": {"env_options": options}})
    env = make_training_env(stage, TrainConfig(), None, "cpu")
    try:
        space = env.unwrapped
        assert len(space.object_set) == len(training_object_set(["blocks:0"])) + FAMILY_SET_SIZE
        assert space.config.scene_tries == 30
        env.reset(seed=11)
        assert space.visuals is not None  # drawn from the episode's seed
    finally:
        env.close()
