"""The env's keywords that name settings refuse a wrong kind of value on one line naming the
keyword and what is valid: ``config`` (each field), ``object_set``, ``camera_config``."""

from __future__ import annotations

import gymnasium as gym
import pytest

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_envs.perception.camera import CameraConfig
from mpg_envs.simulation.objects import load_object_set
from mpg_envs.tasks.config import EnvConfig, check_camera_config, config_of, object_assets


@pytest.mark.parametrize("fields, message", [
    ({"scene_tries": "x"}, "config scene_tries must be an integer >= 1 (draws of a whole scene before InvalidSceneError), got 'x'"),
    ({"scene_tries": 0}, "config scene_tries must be an integer >= 1"),
    ({"scene_tries": True}, "config scene_tries must be an integer >= 1"),
    ({"raycast_threads": 0}, "config raycast_threads must be an integer >= 1 (threads per env for the heightmap, or None"),
    ({"object_set_seed": -1}, "config object_set_seed must be an integer >= 0 (which procedural object set), got -1"),
    ({"generator": 3}, "config generator must be a GeneratorConfig or a dict of its fields, got 3"),
])
def test_a_config_field_of_the_wrong_kind_is_named(fields, message):
    with pytest.raises(ValueError, match="^" + message.replace("(", r"\(").replace(")", r"\)")):
        config_of(fields)


def test_a_config_that_is_no_mapping_lists_the_fields():
    with pytest.raises(TypeError, match=r"^config must be an EnvConfig or a dict of its fields \(e\.g\. \{'scene_tries': 40\}; "
                                        r"valid fields: workspace, robot, .*object_set_seed\), got 'fast'$"):
        config_of("fast")
    assert config_of({"scene_tries": 5, "raycast_threads": 1}).scene_tries == 5
    assert config_of({"generator": {"redrop_rounds": 2}}).generator.redrop_rounds == 2
    assert EnvConfig().raycast_threads is None


def test_object_set_and_camera_config_of_the_wrong_kind_are_named():
    blocks = load_object_set("blocks")
    assert object_assets(blocks[:2]) == blocks[:2] and object_assets(tuple(blocks[:1])) == blocks[:1]
    assert [a.name for a in object_assets("blocks")] == [a.name for a in blocks]
    with pytest.raises(ValueError, match=r"^object_set must be an object set's name \(e\.g\. 'blocks'\), a mesh folder's path or "
                                         r"a list of ObjectAsset, got \[1, 2\] \(it holds 1 of type int\)$"):
        gym.make("MPG-Stage2-v0", object_set=[1, 2])
    with pytest.raises(ValueError, match=r"^object_set must be .*, got 3$"):
        object_assets(3)
    with pytest.raises(ValueError, match="^object_set is empty$"):
        object_assets([])
    with pytest.raises(ValueError, match=r"^camera_config must be None \(the default cameras\) or a CameraConfig, got 3$"):
        gym.make("MPG-Stage2-v0", camera_config=3)
    config = CameraConfig()
    assert check_camera_config(config) is config and check_camera_config(None) is None
