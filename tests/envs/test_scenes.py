"""Valid scenes at every reset, why an episode ended, and scene files that say what is wrong."""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pytest

from conftest import flat_quat
from mpg_envs.tasks.env import END_REASONS, EnvConfig, MPGEnv
from mpg_envs.scenes.scene_io import SceneFile, SceneFileError, objects_outside, read_scene, save_scene
from mpg_envs.scenes.generators import InvalidSceneError, GeneratorConfig, SceneLayout, keep_inside
from mpg_envs.tasks.stages import STAGES, episode_end
from mpg_envs.grid.workspace import Workspace
from mpg_envs.simulation.world import World


# --------------------------------------------------------------------------- valid scenes
@pytest.mark.parametrize(
    "env_id, seed, kwargs",
    [
        ("MPG-Stage1-v0", 0, {}),
        ("MPG-Stage2-v0", 0, {}),
        ("MPG-Stage3-v0", 0, {}),
        ("MPG-Stage4-v0", 0, {}),
        ("MPG-Stage5-v0", 0, {}),  # gave 8 objects of 10 before re-drops
        ("MPG-Occluded-v0", 2, {}),  # had an object outside the workspace
        ("MPG-Occluded-v0", 1, {"num_objects": 30}),  # had 2 outside
    ],
)
def test_reset_gives_every_object_resting_inside_the_workspace(make_env, env_id, seed, kwargs):
    env = make_env(env_id, **kwargs)
    obs, info = env.reset(seed=seed)
    world = env.world
    assert world.num_objects == env.num_objects == int(world.active.sum())
    assert world.objects_outside_workspace().size == 0 and world.objects_at_rest()
    assert info["objects_left"] == env.num_objects
    assert info["occluded"] == bool(obs["occluded"][0])
    if env.stage.name == "Occluded":
        assert env.target in range(5) and info["occluded"]
    if env.stage.name == "Stage5":
        assert env.target in (0, 1) and env.num_objects == 10


def test_stage5_starts_with_ten_objects_on_several_seeds(make_env):
    env = make_env("MPG-Stage5-v0")
    for seed in range(3):
        _, info = env.reset(seed=seed)
        assert info["objects_left"] == 10 == int(env.world.active.sum())


def test_keep_inside_redrops_an_object_that_left_the_workspace(blocks):
    world = World([blocks["cube"], blocks["cube"]])
    world.drop_object(0, (0.5, 0.0), flat_quat())
    world.drop_object(1, (0.52, 0.0), flat_quat())
    world.set_object_pose(1, (0.85, 0.0, 0.03), flat_quat())  # on the table beyond x_max
    world.settle()
    rng = np.random.default_rng(0)
    layout = SceneLayout((0, 1), lambda: np.array([0.5, 0.05]))
    assert keep_inside(world, rng, layout, GeneratorConfig()) == (1,)
    assert world.objects_outside_workspace().size == 0 and world.active.all()
    assert abs(world.object_position(1)[0] - 0.5) < 0.05


def test_reset_raises_when_no_valid_scene_can_be_made():
    impossible = dataclasses.replace(STAGES["Stage5"], start_surrounded=9)  # only 8 sectors exist
    env = MPGEnv(impossible, num_objects=3, config=EnvConfig(scene_tries=2))
    with pytest.raises(InvalidSceneError, match="no valid scene of 3 objects in 2 draws"):
        env.reset(seed=0)


def test_reset_is_deterministic_with_redrops(make_env):
    env = make_env("MPG-Stage5-v0")
    a, _ = env.reset(seed=0)
    b, _ = env.reset(seed=0)
    assert np.array_equal(a["depth"], b["depth"]) and np.array_equal(a["mask"], b["mask"])


# --------------------------------------------------------------------------- end_reason
@pytest.mark.parametrize(
    "stage, kwargs, expected",
    [
        ("Occluded", {}, (False, False, None)),
        ("Occluded", {"is_success": True, "num_motions": 10}, (True, False, "target_grasped")),
        ("Stage1", {"is_success": True}, (True, False, "table_empty")),
        ("Stage3", {"move_success": True, "primitive": "move"}, (True, False, "move_success")),
        ("Occluded", {"move_success": True, "primitive": "move"}, (False, False, None)),
        ("Stage5", {"target_out": True, "num_motions": 10}, (True, False, "target_left_workspace")),
        ("Stage4", {"num_motions": 6}, (False, True, "grasp_done")),
        ("Stage4", {"primitive": "push", "num_motions": 6}, (False, True, "motion_cap")),
        ("Stage5", {"num_motions": 10}, (False, True, "motion_cap")),
    ],
)
def test_episode_end_table(stage, kwargs, expected):
    args = {"is_success": False, "target_out": False, "move_success": False, "primitive": "grasp", "num_motions": 1}
    args.update(kwargs)
    assert episode_end(STAGES[stage], max_motions=STAGES[stage].max_motions, **args) == expected
    assert expected[2] is None or expected[2] in END_REASONS


def corner(env, primitive, rotation=0):
    """An action on an empty corner of the workspace: does nothing to the scene."""
    return env.action_space.encode(primitive, rotation, 2, 2)


def test_end_reason_is_none_until_the_motion_cap(make_env):
    env = make_env("MPG-Stage2-v0", max_motions=2)
    env.reset(seed=0)
    *_, term, trunc, info = env.step(corner(env, "grasp"))
    assert not (term or trunc) and info["end_reason"] is None
    *_, term, trunc, info = env.step(corner(env, "grasp"))
    assert trunc and not term and info["end_reason"] == "motion_cap"


def test_end_reason_grasp_done_in_stage4(make_env):
    env = make_env("MPG-Stage4-v0")
    env.reset(seed=0)
    *_, info = env.step(corner(env, "push"))
    assert info["end_reason"] is None
    *_, term, trunc, info = env.step(corner(env, "grasp"))
    assert trunc and info["end_reason"] == "grasp_done"


def test_end_reason_target_left_workspace(make_env):
    env = make_env("MPG-Stage5-v0")
    env.reset(seed=0)
    env.world.set_object_pose(env.target, (0.85, 0.0, 0.03), flat_quat())  # as if pushed off
    *_, term, trunc, info = env.step(corner(env, "grasp"))
    assert term and info["end_reason"] == "target_left_workspace"


def test_end_reason_move_success_in_stage3(make_env):
    env = make_env("MPG-Stage3-v0", num_objects=2)
    obs, _ = env.reset(seed=0)
    assert obs["occluded"][0]
    env.world.remove_object(1)  # the occluder is lifted away: the next observation is clear
    *_, term, trunc, info = env.step(corner(env, "move"))
    assert term and info["move_success"] and info["end_reason"] == "move_success"


@pytest.mark.parametrize("env_id, reason", [("MPG-Stage2-v0", "target_grasped"), ("MPG-Stage1-v0", "table_empty")])
def test_end_reason_on_success(make_env, env_id, reason):
    from mpg_envs.policies.oracle import OraclePolicy

    env = make_env(env_id, num_objects=1)
    obs, info = env.reset(seed=0)
    policy = OraclePolicy(env)
    for _ in range(env.max_motions):
        obs, _, term, trunc, info = env.step(policy.act(obs))
        if term or trunc:
            break
    assert info["is_success"], "the oracle should grasp a lone object"
    assert info["end_reason"] == reason and reason in END_REASONS


# --------------------------------------------------------------------------- scene files
def vpg_case(vpg_dir, name="test-10-obj-00"):
    return vpg_dir / "test-cases" / f"{name}.txt"


def test_vpg_case_with_objects_outside_raises_naming_them(vpg_dir, make_env):
    env = make_env("MPG-Occluded-v0")
    with pytest.raises(SceneFileError, match=r"outside the workspace.*object 0 \(0\.obj, line 1\) at \(0\.86"):
        env.reset(options={"scene": str(vpg_case(vpg_dir))})


def test_vpg_case_loads_with_drop_outside_and_warns(vpg_dir, make_env):
    env = make_env("MPG-Occluded-v0")
    scene = read_scene(vpg_case(vpg_dir))
    outside = objects_outside(scene, Workspace())
    assert 0 in outside  # the listed target itself lies outside
    with pytest.warns(UserWarning) as record:
        obs, info = env.reset(options={"scene": str(vpg_case(vpg_dir)), "drop_outside": True})
    messages = " ".join(str(w.message) for w in record)
    assert "leaving out" in messages and "object 0 (0.obj, line 1)" in messages
    first_kept = min(set(range(len(scene.objects))) - set(outside))
    assert env.target == first_kept and "is the target" in messages
    assert info["objects_left"] == int(env.world.active.sum()) <= len(scene.objects) - len(outside)
    assert env.world.objects_outside_workspace().size == 0
    assert obs["mask"].any()


def test_unknown_mesh_is_named(tmp_path, make_env):
    case = tmp_path / "cases" / "case.txt"
    case.parent.mkdir()
    case.write_text("5.obj 1 0 0 -0.5 0 0.03 0 0 0\n")  # VPG mesh 5 has no blocks counterpart
    with pytest.raises(SceneFileError, match=r"case.txt:1: unknown mesh '5.obj'"):
        make_env("MPG-Stage5-v0").reset(options={"scene": str(case)})


def saved_scene(env, tmp_path, edit):
    env.reset(seed=3)
    path = save_scene(env, tmp_path / "scene.json")
    doc = json.loads(path.read_text())
    edit(doc)
    path.write_text(json.dumps(doc))
    return path


def test_json_scene_errors_name_what_is_wrong(tmp_path, make_env):
    env = make_env("MPG-Stage5-v0")

    def outside(doc):
        doc["objects"][4]["position"][0] = 0.9

    with pytest.raises(SceneFileError, match=r"object 4 \('\w+'\) at \(0\.900"):
        env.reset(options={"scene": str(saved_scene(env, tmp_path, outside))})
    with pytest.warns(UserWarning, match="leaving out"):
        _, info = env.reset(options={"scene": str(tmp_path / "scene.json"), "drop_outside": True})
    assert info["objects_left"] == 9

    with pytest.raises(SceneFileError, match="has no target; MPG-Stage5-v0 needs one"):
        env.reset(options={"scene": str(saved_scene(env, tmp_path, lambda d: d.update(target=None)))})
    with pytest.raises(SceneFileError, match=r"target is 12; valid: an object index 0\.\.9 \(an integer\), or null for no target"):
        env.reset(options={"scene": str(saved_scene(env, tmp_path, lambda d: d.update(target=12)))})

    def unknown(doc):
        doc["objects"][2]["name"] = "teapot"

    with pytest.raises(SceneFileError, match="object 2 has an unknown asset 'teapot'"):
        env.reset(options={"scene": str(saved_scene(env, tmp_path, unknown))})


def test_scene_io_reads_files_without_an_env(tmp_path, make_env):
    env = make_env("MPG-Stage2-v0")
    env.reset(seed=1)
    path = save_scene(env.current_scene(), tmp_path / "s.json")
    scene = read_scene(path)
    assert isinstance(scene, SceneFile) and scene.target == env.target and scene.stage == "Stage2"
    assert len(scene.objects) == env.world.num_objects
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, info = env.reset(options={"scene": str(path)})
    assert info["objects_left"] == env.num_objects
