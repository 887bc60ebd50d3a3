"""How an env names its target (``target_spec``): the default leaves every registered id's episodes
as they were, the visible mask is the footprint's top surface, and the exemplar tracks are the
hard tracks' scenes recoloured by the look-alike rule, with a query of the target alone."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_envs.scenes.lookalikes import PALETTE, exemplar_colours, rule_breaks
from mpg_envs.scenes.test_sets import find_test_set
from mpg_envs.tasks.target_spec import TARGET_SPECS, exemplar_rng, target_observation_space
from mpg_envs.tasks.tracks import TRACKS

from .episode_digests import RESET_CASES, reset_digests

# Reset digests of every existing id, recorded before the target could be named otherwise (MuJoCo 3.x) and on
# MuJoCo 4, which drops scenes into other poses and ray-casts mesh edges otherwise (tests/envs/episode_digests.py).
DIGESTS = "episode_digests.json" if mujoco.__version__.startswith("3.") else "episode_digests_mujoco4.json"
RECORDED = json.loads((Path(__file__).parent / "data" / DIGESTS).read_text())
NEW_TRACKS = (
    "MPG-OccludedHardVisible-v0",
    "MPG-OccludedHardExemplar-v0",
    "MPG-OccludedHardNovelExemplar-v0",
    "MPG-OccludedHardCameraExemplar-v0",
)


def _case(env_id: str, seed: int):
    """Resets of shipped scenes are fast; drawn scenes and camera images are heavy."""
    fast = seed >= 500000 and "Camera" not in env_id
    return pytest.param(env_id, seed, marks=() if fast else pytest.mark.heavy)


@pytest.mark.parametrize(("env_id", "seed"), [_case(*case) for case in RESET_CASES])
def test_every_existing_id_resets_as_before(env_id, seed):
    assert reset_digests(env_id, seed) == RECORDED[f"{env_id}@{seed}"]


def rollout(env, seed, actions):
    obs, info = env.reset(seed=seed)
    trace = [(obs, info)]
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        trace.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            break
    return trace


def same(a, b):
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and np.array_equal(a, b)
    return a == b


def test_the_mask_spec_named_is_the_default(make_env):
    default, named = (
        make_env("MPG-OccludedHard-v0"),
        make_env("MPG-OccludedHard-v0", target_spec="mask"),
    )
    actions = [int(a) for a in np.random.default_rng(3).integers(default.action_space.n, size=2)]
    assert same(rollout(default, 500002, actions), rollout(named, 500002, actions))
    assert named.observation_space == default.observation_space


def test_the_new_tracks_are_the_hard_stage_with_a_target_spec():
    for env_id in NEW_TRACKS:
        spec = TRACKS[env_id]
        assert spec.stage == "OccludedHard" and spec.options["target_spec"] in TARGET_SPECS
        assert gym.spec(env_id).kwargs == {"stage": "OccludedHard", **spec.options}
    base = {
        k: v
        for k, v in TRACKS["MPG-OccludedHardNovelExemplar-v0"].options.items()
        if k != "target_spec"
    }
    assert base == TRACKS["MPG-OccludedHardNovel-v0"].options
    base = {
        k: v
        for k, v in TRACKS["MPG-OccludedHardCameraExemplar-v0"].options.items()
        if k != "target_spec"
    }
    assert base == TRACKS["MPG-OccludedHardCamera-v0"].options


def test_the_visible_mask_is_the_footprint_where_the_target_shows(make_env):
    hard, visible = make_env("MPG-OccludedHard-v0"), make_env("MPG-OccludedHardVisible-v0")
    assert visible.observation_space == hard.observation_space
    for seed in (500000, 500003):
        (a, info_a), (b, info_b) = hard.reset(seed=seed), visible.reset(seed=seed)
        assert same(info_a, info_b)
        assert all(np.array_equal(a[k], b[k]) for k in ("color", "depth", "occluded"))
        shows = np.isin(
            visible.sim.heightmaps().geom_id, visible.world.object_geom_ids[visible.target]
        )
        assert np.array_equal(b["mask"], (a["mask"] & shows).astype(np.uint8))
        assert b["mask"].sum() == pytest.approx(info_b["visible_fraction"] * a["mask"].sum())
        assert b["mask"].sum() < a["mask"].sum()  # the hard track's targets are covered


def test_a_hidden_target_has_an_empty_visible_mask(make_env):
    env = make_env("MPG-OccludedHardVisible-v0")
    hidden = find_test_set("occluded_hard", 15)
    seed = int(hidden.seeds[np.flatnonzero(hidden.visible_fraction == 0)[0]])
    obs, info = env.reset(seed=seed)
    assert info["visible_fraction"] == 0 and not obs["mask"].any()


def test_an_exemplar_scene_is_the_hard_scene_recoloured(make_env):
    hard, exemplar = make_env("MPG-OccludedHard-v0"), make_env("MPG-OccludedHardExemplar-v0")
    assert set(exemplar.observation_space.spaces) == {
        "color",
        "depth",
        "query_color",
        "query_depth",
    }
    actions = [int(a) for a in np.random.default_rng(5).integers(hard.action_space.n, size=1)]
    a, b = rollout(hard, 500001, actions), rollout(exemplar, 500001, actions)
    assert exemplar.observation_space.contains(b[0][0]) and set(b[0][0]) == {
        "color",
        "depth",
        "query_color",
        "query_depth",
    }
    for (obs_a, *rest_a), (obs_b, *rest_b) in zip(a, b):
        assert np.array_equal(obs_a["depth"], obs_b["depth"])  # the same physics, step for step
        table = obs_a["depth"] == 0
        assert np.array_equal(
            obs_a["color"][table], obs_b["color"][table]
        )  # only the objects' colours change
        info_a, info_b = rest_a[-1], rest_b[-1]
        assert {
            k: v
            for k, v in info_b.items()
            if k not in ("lookalikes", "wrong_grasp_lookalike", "wrong_grasp_shares")
        } == info_a


def test_exemplar_colours_follow_the_rule_and_the_query_shows_the_target(make_env):
    env = make_env("MPG-OccludedHardExemplar-v0")
    test_set = find_test_set("occluded_hard", 15)
    for seed in (500000, 500004):
        obs, info = env.reset(seed=seed)
        k = int(np.flatnonzero(test_set.seeds == seed)[0])
        names = [str(n) for n in test_set.assets[k]]
        expected = exemplar_colours(names, int(test_set.targets[k]), exemplar_rng(seed, 0))
        assert env.naming.colours == expected and rule_breaks(names, expected, env.target) == []
        rgba = np.round(np.array(PALETTE)[list(expected)] * 255)
        for i, geoms in enumerate(env.world.object_geom_ids):
            assert np.allclose(np.round(env.world.model.geom_rgba[geoms] * 255), rgba[i])
        others = [i for i in range(len(names)) if i != env.target]
        assert info["lookalikes"] == {
            "colour": sum(expected[i] == expected[env.target] for i in others),
            "shape": sum(names[i] == names[env.target] for i in others),
        }
        above = obs["query_depth"] > 0.005
        assert 100 < above.sum() < 3000  # one block alone
        target_colour = np.round(np.array(PALETTE[expected[env.target]][:3]) * 255)
        assert np.all(obs["query_color"][above] == target_colour)
        extents = env.world.assets[env.target].extents
        assert (
            extents.min() - 0.003 <= obs["query_depth"].max() <= extents.max() + 0.003
        )  # resting on the table


def test_the_exemplar_is_drawn_from_the_seed_alone(make_env):
    env, other = make_env("MPG-OccludedHardExemplar-v0"), make_env("MPG-OccludedHardExemplar-v0")
    first, _ = env.reset(seed=500003)
    env.reset(seed=500004)
    again, _ = env.reset(seed=500003)
    fresh, _ = other.reset(seed=500003)
    assert same(first, again) and same(first, fresh)


@pytest.mark.heavy
def test_exemplar_episodes_of_drawn_scenes(make_env):
    env = make_env("MPG-OccludedHardExemplar-v0")
    first, _ = env.reset(seed=700003)
    again, _ = make_env("MPG-OccludedHardExemplar-v0").reset(seed=700003)
    assert same(first, again)
    unseeded, info = env.reset()
    assert set(unseeded) == set(first) and info["lookalikes"]["colour"] >= 1


def test_a_mis_pick_says_what_it_shared(make_env):
    env = make_env("MPG-OccludedHardExemplar-v0")
    env.reset(seed=500000)
    looks = env.naming.step_info(
        True,
        next(
            i
            for i in range(env.world.num_objects)
            if i != env.target and env.naming.colours[i] == env.naming.colours[env.target]
        ),
    )
    assert looks == {"wrong_grasp_lookalike": True, "wrong_grasp_shares": ("colour",)}
    assert env.naming.step_info(False, None) == {
        "wrong_grasp_lookalike": False,
        "wrong_grasp_shares": (),
    }


def test_bad_target_specs_are_refused(make_env):
    with pytest.raises(
        ValueError,
        match=r"target_spec must be one of \('mask', 'visible', 'exemplar'\), got 'query'",
    ):
        make_env("MPG-OccludedHard-v0", target_spec="query")
    with pytest.raises(
        ValueError, match="target_spec='exemplar' needs a target; MPG-Stage1-v0 has none"
    ):
        make_env("MPG-Stage1-v0", target_spec="exemplar")
    assert set(target_observation_space("exemplar").spaces) == {
        "color",
        "depth",
        "query_color",
        "query_depth",
    }


@pytest.mark.parametrize("name", ["occluded_hard", "occluded_hard_novel"])
@pytest.mark.parametrize("num_objects", [15, 30])
def test_the_rule_holds_on_every_shipped_test_scene(name, num_objects):
    test_set = find_test_set(name, num_objects)
    assert len(test_set) == 500 and test_set.seeds[0] == 500000
    shared_colour = 0
    for seed, assets, target in zip(test_set.seeds, test_set.assets, test_set.targets):
        names = [str(n) for n in assets]
        colours = exemplar_colours(names, int(target), exemplar_rng(int(seed), 0))
        assert rule_breaks(names, colours, int(target)) == [], seed
        others = [i for i in range(len(names)) if i != target]
        assert all(colours[i] != colours[target] for i in others if names[i] == names[target])
        shared_colour += any(colours[i] == colours[target] for i in others)
    assert shared_colour >= 0.9 * len(test_set)


def test_the_visible_track_is_the_hard_track_step_for_step(make_env):
    # A policy that reads no observation (random, the oracle) plays the same episode on both.
    hard, visible = make_env("MPG-OccludedHard-v0"), make_env("MPG-OccludedHardVisible-v0")
    actions = [int(a) for a in np.random.default_rng(8).integers(hard.action_space.n, size=3)]
    a, b = rollout(hard, 500002, actions), rollout(visible, 500002, actions)
    assert len(a) == len(b)
    for (obs_a, *rest_a), (obs_b, *rest_b) in zip(a, b):
        assert np.array_equal(obs_a["depth"], obs_b["depth"]) and np.array_equal(obs_a["color"], obs_b["color"])
        assert not np.any(obs_b["mask"] & ~obs_a["mask"])  # the visible mask is inside the whole one
        assert same(rest_a, rest_b)
