"""The unseen-object track (``MPG-OccludedHardNovel-v0``): registered, its objects are pybullet's
``random_urdfs`` test split only, it resets from its shipped test set without pybullet, and the
project's training refuses its objects."""

from __future__ import annotations

import hashlib
import json
import re
import sys

import gymnasium as gym
import numpy as np
import pytest

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_envs.scenes.generators import GeneratorConfig
from mpg_envs.scenes.scene_io import read_scene, save_scene
from mpg_envs.scenes.test_sets import TEST_SEED_START, find_test_set, test_set_name
from mpg_envs.simulation import meshes, random_urdfs
from mpg_envs.simulation.gripper_fit import BLOCKS_EXTENTS
from mpg_envs.simulation.object_packs import load_object_pack, read_pack_meta, save_object_pack
from mpg_envs.simulation.objects import (
    HELD_OUT_OBJECT_SETS, HeldOutObjectsError, check_not_held_out, held_out_objects, load_object_set,
)  # fmt: skip
from mpg_envs.tasks.config import EnvConfig, config_of
from mpg_envs.tasks.tracks import NOVEL_GENERATOR, NOVEL_SCENE_TRIES, TRACKS

TRACK = "MPG-OccludedHardNovel-v0"


@pytest.fixture(scope="module")
def pack():
    return load_object_set("random_urdfs_test")


def test_the_track_is_registered_as_the_hard_stage_on_the_held_out_objects():
    spec = TRACKS[TRACK]
    assert spec.stage == "OccludedHard" and spec.options["object_set"] == "random_urdfs_test"
    # Only the scene draws and the generator's settings differ from the defaults.
    assert config_of(spec.options["config"]) == EnvConfig(scene_tries=NOVEL_SCENE_TRIES, generator=GeneratorConfig(**NOVEL_GENERATOR))
    assert gym.spec(TRACK).kwargs == {"stage": "OccludedHard", **spec.options}
    assert gym.spec(TRACK).max_episode_steps == 10
    assert "random_urdfs_test" in HELD_OUT_OBJECT_SETS
    assert test_set_name("occluded_hard", "random_urdfs_test") == "occluded_hard_novel"
    assert test_set_name("occluded_hard", "blocks") == "occluded_hard" and test_set_name("occluded_hard", "/my/meshes") is None


def test_its_objects_are_the_test_split_only_fitted_to_the_gripper(pack):
    meta = read_pack_meta(random_urdfs.test_pack_path())
    numbers = json.loads(meta["numbers"])
    left_out = json.loads(meta["left_out"])
    assert [a.name for a in pack] == [f"random_urdf_{n:03d}" for n in numbers]
    assert all(n % 10 == 0 for n in numbers) and all(int(k) % 10 == 0 for k in left_out)
    assert sorted(numbers + [int(k) for k in left_out]) == list(range(0, 1000, 10))  # every test object, each kept or left out with a reason
    assert meta["licence"] == "zlib" and "random_urdfs" in meta["source"]
    for asset in pack:
        number = int(asset.name[-3:])
        assert asset.source == f"pybullet_data/random_urdfs/{number:03d}/{number:03d}.obj" and asset.licence == "zlib"
        assert BLOCKS_EXTENTS.contains(asset.extents, tolerance=1e-6), asset.name
        assert asset.scale > 0 and asset.mass > 0
    assert held_out_objects(pack) == [a.name for a in pack]
    licence = (random_urdfs.test_pack_path().parent / meta["licence_file"]).read_text()
    assert "zlib" in licence and "freely" in licence and "Bullet" in licence


def test_an_object_pack_round_trips(tmp_path, pack):
    path = save_object_pack(tmp_path / "p.npz", pack[:3], {"source": "here"})
    again = load_object_pack(path)
    assert read_pack_meta(path)["source"] == "here"
    for a, b in zip(pack[:3], again):
        assert (a.name, a.rgba, a.mass, a.friction, a.scale, a.mesh_offset, a.source, a.licence) == (
            b.name, b.rgba, b.mass, b.friction, b.scale, b.mesh_offset, b.source, b.licence,
        )  # fmt: skip
        for (va, fa), (vb, fb) in zip(a.parts, b.parts):
            np.testing.assert_array_equal(fa, fb)
            np.testing.assert_allclose(va, vb, atol=1e-7)  # float32 storage
    with pytest.raises(ValueError, match="unique"):
        save_object_pack(tmp_path / "q.npz", [pack[0], pack[0]])
    np.savez(tmp_path / "other.npz", x=np.zeros(2))
    with pytest.raises(ValueError, match="not an mpg-object-pack"):
        load_object_pack(tmp_path / "other.npz")


def test_the_shipped_test_set_holds_the_held_out_seeds_made_with_the_shipped_pack():
    digest = hashlib.sha256(random_urdfs.test_pack_path().read_bytes()).hexdigest()
    for objects in (15, 30):
        test_set = find_test_set("occluded_hard_novel", objects)
        assert test_set is not None and len(test_set) >= 1
        assert test_set.seeds[0] == TEST_SEED_START and np.all(np.diff(test_set.seeds) == 1)
        assert test_set.meta["env_id"] == TRACK and test_set.meta["object_set"] == "random_urdfs_test"
        assert test_set.meta["object_pack_sha256"] == digest
        assert test_set.visible_fraction.max() <= 0.3
        assert all(re.fullmatch(r"random_urdf_\d\d0", name) for name in test_set.assets.ravel())


def test_it_resets_from_its_shipped_test_set_without_pybullet(monkeypatch, tmp_path):
    # No pybullet, and no mesh decomposition: the pack and the scenes are all a reset reads.
    for name in ("pybullet", "pybullet_data"):
        monkeypatch.setitem(sys.modules, name, None)  # import raises ImportError

    def no_source(*args, **kwargs):
        raise AssertionError("the track must not read pybullet's meshes")

    monkeypatch.setattr(random_urdfs, "random_urdfs_folder", no_source)
    monkeypatch.setattr(meshes, "load_mesh_file", no_source)
    env = gym.make(TRACK).unwrapped
    test_set = find_test_set("occluded_hard_novel", 15)
    k = len(test_set) - 1
    _, info = env.reset(seed=TEST_SEED_START + k)
    assert info["target"] == test_set.targets[k] and info["occluded"]
    assert info["visible_fraction"] == pytest.approx(test_set.visible_fraction[k], abs=1e-6)
    for i in range(15):
        np.testing.assert_array_equal(env.world.object_position(i), test_set.positions[k, i])
    assert [o.asset.name for o in env.current_scene().objects] == test_set.assets[k].tolist()
    # A saved scene of the track reads back with the packed objects (its sources are the set's paths).
    again = read_scene(save_scene(env.current_scene(), tmp_path / "scene.json"))
    assert [o.asset.name for o in again.objects] == test_set.assets[k].tolist() and again.target == test_set.targets[k]
    np.testing.assert_array_equal(again.objects[0].asset.parts[0][0], env.object_set[[a.name for a in env.object_set].index(again.objects[0].asset.name)].parts[0][0])


def test_training_refuses_the_held_out_objects(tmp_path, pack):
    from mpg_agents.learning.learner import Learner
    from mpg_agents.learning.train_config import TrainConfig

    with pytest.raises(HeldOutObjectsError, match="held out for testing"):
        Learner(TrainConfig(steps=1), TRACK, tmp_path / "run")
    assert not (tmp_path / "run").exists()  # refused before anything is written
    with pytest.raises(HeldOutObjectsError, match="random_urdfs_test"):
        check_not_held_out("random_urdfs_test")
    with pytest.raises(HeldOutObjectsError, match="random_urdf_010|random_urdf_0"):
        check_not_held_out("custom", pack[:2])  # objects passed as a list are caught by name
    check_not_held_out("blocks", load_object_set("blocks"))  # the blocks train as before
    assert random_urdfs.is_test_object("x", "/site-packages/pybullet_data/random_urdfs/230/230.obj")
    assert not random_urdfs.is_test_object("random_urdf_231", "/site-packages/pybullet_data/random_urdfs/231/231.obj")


def test_its_generator_settings_are_checked_and_any_of_the_first_five_may_be_the_target():
    from mpg_envs.scenes.generators import buried_test_cluster
    from mpg_envs.simulation.world import World

    for bad in ({"buried_candidates": 0}, {"drop_settle_steps": 0}, {"buried_candidates": 2.0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            GeneratorConfig(**bad)
    blocks = load_object_set("blocks")
    world = World(blocks[:6], robot_visual=False)
    quick = {"drop_settle_steps": 20, "drop_timestep": 0.004}
    layout = buried_test_cluster(world, np.random.default_rng(0), GeneratorConfig(buried_candidates=5, **quick))
    assert layout.targets[0] == 0 and sorted(layout.targets[1:]) == [1, 2, 3, 4]  # the buried one first
    assert world.model.opt.timestep == 0.002  # the drops' timestep is the drops' alone
    world.reset()
    assert buried_test_cluster(world, np.random.default_rng(0), GeneratorConfig(**quick)).targets == (0,)  # the blocks' rule


def test_a_test_set_is_used_only_with_the_generator_settings_it_was_made_with():
    from mpg_envs.tasks.scene_source import scene_from_test_set

    blocks = gym.make("MPG-OccludedHard-v0").unwrapped
    assert scene_from_test_set(blocks.scene_request, TEST_SEED_START) is not None
    other = gym.make("MPG-OccludedHard-v0", config={"generator": {"buried_candidates": 5}}).unwrapped
    assert scene_from_test_set(other.scene_request, TEST_SEED_START) is None  # dropped afresh: its scenes are not the set's
    novel = gym.make(TRACK).unwrapped
    assert find_test_set("occluded_hard_novel", 15).generator_config == novel.config.generator == GeneratorConfig(**NOVEL_GENERATOR)
    assert scene_from_test_set(novel.scene_request, TEST_SEED_START) is not None
