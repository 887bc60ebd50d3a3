"""Visible fraction, strict retrieval, visibility bands, the hard track and the shipped test sets."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import mpg_envs  # noqa: F401
from mpg_envs.tasks.config import EnvConfig
from mpg_envs.tasks.env import MPGEnv
from mpg_envs.perception.occlusion import VISIBILITY_BAND_LABELS, VISIBILITY_BANDS, check_band, in_band, visibility_band, visible_fraction
from mpg_envs.scenes.scene_io import SceneFile, SceneObject
from mpg_envs.scenes.generators import InvalidSceneError
from mpg_envs.scenes.test_sets import TEST_SEED_START, find_test_set, load_test_set, shipped_set_path
from mpg_envs.grid.workspace import world_to_pixel

UPRIGHT = np.array([1.0, 0.0, 0.0, 0.0])


# ------------------------------------------------------------------ pure functions
def test_visible_fraction_counts_footprint_pixels_where_the_target_is_on_top():
    mask = np.zeros((4, 4), np.uint8)
    mask[1:3, 1:3] = 1  # 4 footprint pixels
    top = np.full((4, 4), -1, np.int32)
    top[1, 1] = 7  # the target's geom
    top[1, 2] = 8  # the target's other part
    top[2, 1] = 3  # another object on top
    top[2, 2] = 3
    top[0, 0] = 7  # outside the footprint: does not count
    assert visible_fraction(mask, top, np.array([7, 8])) == 0.5
    assert visible_fraction(mask, top, np.array([9])) == 0.0
    assert visible_fraction(np.zeros((4, 4), np.uint8), top, np.array([7])) is None
    with pytest.raises(ValueError, match="same shape"):
        visible_fraction(mask, top[:3], np.array([7]))


def test_visibility_bands_cover_zero_to_one_once():
    assert [visibility_band(v) for v in (0.0, 0.05, 0.1, 0.29, 0.3, 0.6, 0.99, 1.0)] == [
        "0-0.1", "0-0.1", "0.1-0.3", "0.1-0.3", "0.3-0.6", "0.6-1", "0.6-1", "0.6-1"
    ]
    assert visibility_band(None) is None and len(VISIBILITY_BANDS) == 4
    assert VISIBILITY_BAND_LABELS == ("0-0.1", "0.1-0.3", "0.3-0.6", "0.6-1")
    with pytest.raises(ValueError, match="lies in"):
        visibility_band(1.5)


def test_bands_are_checked_and_closed():
    assert check_band((0, 0.3)) == (0.0, 0.3) and check_band(None) is None
    assert in_band(0.3, (0.0, 0.3)) and not in_band(0.31, (0.0, 0.3)) and not in_band(None, (0.0, 1.0))
    for bad in ((0.5, 0.2), (-0.1, 0.3), (0.0, 1.5), "low", (0.1,)):
        with pytest.raises(ValueError, match="visible_range"):
            check_band(bad)


# ------------------------------------------------------------------ strict retrieval
def _two_cubes(blocks) -> SceneFile:
    z = float(blocks["cube"].extents[2]) / 2
    cube = blocks["cube"]
    return SceneFile((SceneObject(cube, np.array([0.45, -0.1, z]), UPRIGHT), SceneObject(cube, np.array([0.55, 0.1, z]), UPRIGHT)), 0)


def _grasp_other_cube(env: MPGEnv):
    row, col = world_to_pixel(env.config.workspace, 0.55, 0.1)
    return env.step(env.action_space.encode("grasp", 0, row, col))


def test_strict_retrieval_ends_a_mis_pick_as_a_failure(blocks):
    env = MPGEnv("Occluded", wrong_grasp="fail")
    obs, info = env.reset(options={"scene": _two_cubes(blocks)})
    assert info["visible_fraction"] == 1.0 and info["target"] == 0
    _, reward, terminated, truncated, info = _grasp_other_cube(env)
    assert info["wrong_grasp"] and info["grasp_success"] and not info["is_success"]
    assert (terminated, truncated, info["end_reason"]) == (True, False, "wrong_object")
    assert reward == env.config.reward.wrong_object == -1.0


def test_the_papers_protocol_removes_a_mis_picked_object_and_goes_on(blocks):
    env = MPGEnv("Occluded")  # wrong_grasp="remove" by default
    env.reset(options={"scene": _two_cubes(blocks)})
    _, reward, terminated, truncated, info = _grasp_other_cube(env)
    assert info["wrong_grasp"] and reward == 0.0 and not terminated and not truncated
    assert info["end_reason"] is None and info["objects_left"] == 1


def test_strict_retrieval_and_bands_need_a_target_and_valid_values():
    with pytest.raises(ValueError, match="wrong_grasp must be one of"):
        MPGEnv("Occluded", wrong_grasp="drop")
    with pytest.raises(ValueError, match="needs a target"):
        MPGEnv("Stage1", wrong_grasp="fail")
    with pytest.raises(ValueError, match="needs a target"):
        MPGEnv("Stage1", visible_range=(0.0, 0.5))
    assert gym.make("MPG-OccludedHard-v0").unwrapped.wrong_grasp == "fail"


# ------------------------------------------------------------------ bands and the hard track
def test_a_band_of_low_visibility_is_made_by_burying_the_target():
    env = gym.make("MPG-OccludedHard-v0", num_objects=8)  # no shipped set at 8 objects: generated
    for seed in (1, 2):
        obs, info = env.reset(seed=seed)
        assert info["visible_fraction"] <= 0.3 and info["occluded"] and info["objects_left"] == 8
        assert obs["occluded"][0] == 1
    _, _, _, _, step_info = env.step(env.action_space.sample())
    assert step_info["visible_fraction"] is None or 0.0 <= step_info["visible_fraction"] <= 1.0


def test_a_band_no_scene_can_meet_raises_instead_of_returning_a_lesser_scene():
    env = MPGEnv("Stage2", visible_range=(0.0, 0.05), config=EnvConfig(scene_tries=2))
    with pytest.raises(InvalidSceneError, match="visible fraction"):
        env.reset(seed=0)


def test_num_objects_is_a_reset_option():
    env = MPGEnv("Stage2", num_objects=3)
    _, info = env.reset(seed=0, options={"num_objects": 4})
    assert info["objects_left"] == 4 and env.num_objects == 4
    _, info = env.reset(seed=0)
    assert info["objects_left"] == 3
    with pytest.raises(ValueError, match="num_objects must be an integer"):
        env.reset(seed=0, options={"num_objects": 0})


# ------------------------------------------------------------------ shipped test sets
@pytest.mark.parametrize("name", ["occluded", "occluded_hard"])
@pytest.mark.parametrize("objects", [15, 30])
def test_test_sets_ship_500_scenes_from_the_held_out_seeds(name, objects):
    test_set = find_test_set(name, objects)
    assert test_set is not None and len(test_set) >= 500
    assert test_set.seeds[0] == TEST_SEED_START and np.all(np.diff(test_set.seeds) == 1)
    assert test_set.meta["generator_version"] == "1" and test_set.meta["env_id"].startswith("MPG-Occluded")
    if name == "occluded_hard":
        assert test_set.visible_fraction.max() <= 0.3
    assert load_test_set(shipped_set_path(name, objects)).seeds.shape == test_set.seeds.shape


def test_a_test_id_loads_its_shipped_scene_and_other_seeds_are_generated():
    env = gym.make("MPG-OccludedHard-v0").unwrapped
    test_set = find_test_set("occluded_hard", 15)
    _, info = env.reset(seed=TEST_SEED_START + 3)
    k = 3
    assert info["target"] == test_set.targets[k] and info["visible_fraction"] == pytest.approx(test_set.visible_fraction[k], abs=1e-6)
    for i in range(15):
        np.testing.assert_array_equal(env.world.object_position(i), test_set.positions[k, i])
    assert gym.make("MPG-OccludedHard-v0", use_test_set=False).unwrapped.use_test_set is False


def test_a_test_scene_gives_the_same_observation_in_two_processes():
    code = (
        "import hashlib, gymnasium as gym, mpg_envs; e = gym.make('MPG-Occluded-v0', num_objects=30); "
        "o, i = e.reset(seed=500007); print(hashlib.sha256(b''.join(o[k].tobytes() for k in sorted(o))).hexdigest(), i['visible_fraction'])"
    )
    outs = {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True).stdout for _ in range(2)}
    assert len(outs) == 1 and len(next(iter(outs)).split()) == 2


def test_the_hard_track_bound_has_one_owner():
    from mpg_envs.tasks.stages import HARD_VISIBLE_MAX, STAGES

    assert HARD_VISIBLE_MAX == 0.3  # the shipped hard test scenes were drawn with it
    assert STAGES["OccludedHard"].visible_range == (0.0, HARD_VISIBLE_MAX)
    assert gym.spec("MPG-OccludedHardNovel-v0").kwargs.get("visible_range") is None  # the stage's, not a copy
