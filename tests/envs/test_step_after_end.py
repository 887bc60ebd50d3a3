"""``step()`` runs only inside an episode: after its end, before the first ``reset()`` and after
``close()`` it raises, until the next ``reset()``; env keywords are typed."""

import pytest


def corner(env, primitive, rotation=0):
    """An action on an empty corner of the workspace: does nothing to the scene."""
    return env.action_space.encode(primitive, rotation, 2, 2)


def test_step_before_reset_raises(make_env):
    env = make_env("MPG-Stage2-v0")
    with pytest.raises(RuntimeError, match=r"call reset\(\) before step\(\)"):
        env.step(corner(env, "grasp"))


def test_step_after_a_truncated_episode_raises_until_reset(make_env):
    env = make_env("MPG-Stage2-v0", max_motions=1)
    env.reset(seed=0)
    *_, terminated, truncated, info = env.step(corner(env, "grasp"))
    assert truncated and info["end_reason"] == "motion_cap"
    with pytest.raises(RuntimeError, match=r"the episode has ended \(motion_cap\); call reset\(\) before step\(\)"):
        env.step(corner(env, "grasp"))
    with pytest.raises(RuntimeError, match=r"the episode has ended \(motion_cap\); call reset\(\) before try_step\(\)"):
        env.try_step(corner(env, "grasp"))
    env.reset(seed=0)
    *_, info = env.step(corner(env, "grasp"))
    assert info["num_motions"] == 1


def test_step_after_a_terminated_episode_raises(make_env):
    """A success ends the episode; stepping on cannot score another."""
    from mpg_envs.policies.oracle import OraclePolicy

    env = make_env("MPG-Stage2-v0", num_objects=1)
    obs, _ = env.reset(seed=0)
    policy = OraclePolicy(env)
    for _ in range(env.max_motions):
        obs, _, terminated, truncated, info = env.step(policy.act(obs))
        if terminated or truncated:
            break
    assert terminated and info["is_success"] and info["end_reason"] == "target_grasped"
    with pytest.raises(RuntimeError, match=r"the episode has ended \(target_grasped\); call reset\(\) before step\(\)"):
        env.step(corner(env, "grasp"))


def test_try_step_leaves_the_episode_open(make_env):
    env = make_env("MPG-Stage2-v0", max_motions=1)
    env.reset(seed=0)
    *_, truncated, _ = env.try_step(corner(env, "grasp"))  # would end it, but is undone
    assert truncated
    *_, truncated, _ = env.step(corner(env, "grasp"))
    assert truncated


def test_step_after_close_raises_and_reset_reopens(make_env):
    env = make_env("MPG-Stage2-v0")
    env.reset(seed=0)
    env.close()
    with pytest.raises(RuntimeError, match=r"the env is closed; call reset\(\) to start a new episode before step\(\)"):
        env.step(corner(env, "grasp"))
    env.reset(seed=0)
    *_, info = env.step(corner(env, "grasp"))
    assert info["num_motions"] == 1


@pytest.mark.parametrize("value", ["no", 1, None])
def test_use_test_set_must_be_a_bool(make_env, value):
    with pytest.raises(ValueError, match=rf"use_test_set must be True or False, got {value!r}"):
        make_env("MPG-Stage2-v0", use_test_set=value)


def test_step_after_a_reset_that_raised_raises_until_a_reset_completes(make_env, tmp_path):
    """A reset that raises (a missing file, objects inside each other) leaves no episode to step in:
    not the old one, nor the half-built world of the new one."""
    import json

    from mpg_envs.scenes.scene_io import SceneFileError, save_scene

    env = make_env("MPG-Stage2-v0")
    env.reset(seed=0)
    doc = json.loads(save_scene(env, tmp_path / "scene.json").read_text())
    doc["objects"][1]["position"] = doc["objects"][0]["position"]
    (tmp_path / "inside.json").write_text(json.dumps(doc))
    raised = r"the last reset\(\) raised; call reset\(\) before "
    for scene, error in ((tmp_path / "missing.json", FileNotFoundError), (tmp_path / "inside.json", SceneFileError)):
        env.reset(seed=0)
        with pytest.raises(error):
            env.reset(options={"scene": str(scene)})
        with pytest.raises(RuntimeError, match=raised + r"step\(\)"):
            env.step(corner(env, "grasp"))
        with pytest.raises(RuntimeError, match=raised + r"try_step\(\)"):
            env.try_step(corner(env, "grasp"))
        with pytest.raises(RuntimeError, match=r"call reset\(\) before current_scene\(\)"):
            env.current_scene()
        assert env.last_observation is None and env.target is None
    env.reset(options={"scene": str(tmp_path / "scene.json")})
    *_, info = env.step(corner(env, "grasp"))
    assert info["num_motions"] == 1
