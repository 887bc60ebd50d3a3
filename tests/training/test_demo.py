"""The README's demo command runs end to end and writes pictures that say what they show."""

import cv2

import mpg_envs.perception.render as render_module
from mpg_agents.evaluation.policy_zoo import shipped_checkpoint
from mpg_agents.demo import PANEL_PX, TITLE_PX, main

# The Stage I-II grasp net (the learned Grasping-Only of the earlier release), kept beside
# the shipped MPGNet: its first action on an occluded scene is a grasp.
GRASP_NET = str(shipped_checkpoint().parent / "stage2_grasp_small.safetensors")


def test_shipped_checkpoint_is_small_and_loads():
    path = shipped_checkpoint()
    assert path.stat().st_size < 10 * 2**20
    from mpg_agents.acting.weights import read_checkpoint_header

    header = read_checkpoint_header(path)
    assert header["primitives"] == ["move", "push", "grasp"] and header["variant"] == "small"
    assert header["q_star"] is not None  # chosen after training, training's on record
    assert header["extra"]["q_star_from_training"] is not None
    assert header["config"]["grasp_region"] == "target" and header["config"]["target_margin_px"] == -8
    assert header["config"]["grasp_fingers"] == "clear"


def test_demo_runs_the_shipped_policy_which_moves_the_occluder_then_grasps_the_target(tmp_path, capsys):
    # The README's demo: on a held-out hard-track scene the shipped MPGNet moves the occluder
    # aside, then takes the target, and pictures the three Q maps before each motion.
    assert main(["--episodes", "1", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "task success 1/1" in out and "mean motions" in out and "torch threads" in out
    assert "MPG-OccludedHard-v0" in out
    steps = [line for line in out.splitlines() if "episode 0 motion" in line]
    assert [line.split(":")[1].split()[0] for line in steps] == ["move", "grasp"]
    assert steps[0].endswith("uncovered the target") and steps[1].endswith("grasped the target")
    for name in ("scene.png", "qmaps_1.png", "qmaps_2.png"):
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"
    scene = cv2.imread(str(tmp_path / "scene.png"))
    assert scene.shape[0] == TITLE_PX + PANEL_PX
    # Two heightmap panels, and the rendered view unless this machine has no OpenGL.
    assert scene.shape[1] > 2 * PANEL_PX or "no rendered view" in out
    assert (scene[:TITLE_PX].max(axis=-1) > 200).sum() > 100  # titles


def test_demo_without_opengl_says_so_and_writes_the_heightmaps(tmp_path, capsys, monkeypatch):
    # As after a failed GL context: render() raises without touching OpenGL.
    monkeypatch.setattr(render_module, "_gl_failure", "could not create an OpenGL context (test)")
    assert main(["--policy", "random", "--episodes", "1", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "no rendered view in scene.png" in out and "MUJOCO_GL" in out
    scene = cv2.imread(str(tmp_path / "scene.png"))
    assert scene.shape == (TITLE_PX + PANEL_PX, 2 * PANEL_PX, 3)
    assert not list(tmp_path.glob("qmaps*.png"))  # a random policy has no Q maps


def test_grasp_net_with_grasps_kept_on_the_target():
    import gymnasium as gym

    from mpg_agents.evaluation.policy_zoo import make_policy
    from mpg_envs.grid.actions import decode_action

    env = gym.make("MPG-Occluded-v0", num_objects=15)
    policy = make_policy(GRASP_NET, env, grasp_region="target")
    assert policy.policy.q_net.mpgnet.config.grasp_region == "target" and policy.name.endswith("[grasp region: target]")
    obs, _ = env.reset(seed=700_003)
    a = decode_action(env.unwrapped.primitives, policy.act(obs))
    rows, cols = (obs["mask"] > 0).nonzero()
    near = (abs(rows - a.row) <= 2) & (abs(cols - a.col) <= 2)  # within the 2-pixel margin of a target pixel
    assert a.primitive == "grasp" and near.any()
    env.close()


def test_grasps_kept_off_the_target_rim():
    import gymnasium as gym
    import torch

    from mpg_agents.evaluation.policy_zoo import make_policy
    from mpg_agents.network.regions import target_pixels
    from mpg_envs.grid.actions import decode_action

    env = gym.make("MPG-Stage2-v0")
    policy = make_policy(GRASP_NET, env, grasp_region="target", target_margin_px=-8)
    assert policy.name.endswith("[grasp region: target] [target margin: -8 px]")
    obs, _ = env.reset(seed=900_000)
    a = decode_action(env.unwrapped.primitives, policy.act(obs))
    interior = target_pixels(torch.from_numpy(obs["mask"][None] > 0), -8)[0].numpy()
    assert interior[a.row, a.col] and interior.sum() < (obs["mask"] > 0).sum()
    env.close()


def test_moves_kept_on_the_occluders_top():
    import gymnasium as gym
    import torch

    from mpg_agents.evaluation.policy_zoo import make_policy
    from mpg_agents.network.regions import footprint_top
    from mpg_envs.grid.actions import decode_action

    env = gym.make("MPG-Occluded-v0", num_objects=15)
    # The paper's workflow sends an occluded target to the move net whatever the grasp Q
    # (the shipped net's own grasp_first rule may grasp through the cover instead).
    policy = make_policy("shipped", env, move_region="top", coordination="workflow")
    # The shipped net pushes once after 3 failed grasps in a row (grasp retries in its header).
    assert policy.name.endswith("[move region: top] [push after 3 failed grasps]")
    obs, _ = env.reset(seed=700_003)
    assert obs["occluded"][0] == 1
    a = decode_action(env.unwrapped.primitives, policy.act(obs))
    top = footprint_top(torch.from_numpy(obs["mask"][None] > 0), torch.from_numpy(obs["depth"][None]), 0.015)[0].numpy()
    mask = obs["mask"] > 0
    assert a.primitive == "move" and top[a.row, a.col] and top.sum() < mask.sum()
    assert obs["depth"][a.row, a.col] > obs["depth"][mask].min() + 0.015  # on something above the target's lowest
    env.close()


def test_avoid_repeats_never_takes_an_action_again_on_an_unchanged_scene():
    import gymnasium as gym

    from mpg_agents.evaluation.policy_zoo import make_policy
    from mpg_envs.grid.actions import decode_action

    env = gym.make("MPG-Occluded-v0", num_objects=15)
    obs, _ = env.reset(seed=700_003)
    plain = make_policy(GRASP_NET, env)
    policy = make_policy(GRASP_NET, env, avoid_repeats=True)
    assert policy.name.endswith("[no repeats]")
    prims = env.unwrapped.primitives
    first = decode_action(prims, policy.act(obs))
    assert plain.act(obs) == plain.act(obs) == encode(prims, first)  # memoryless: the same action forever
    second = decode_action(prims, policy.act(obs))  # the same observation: the scene did not change
    assert (second.rotation % 8 != first.rotation % 8) or max(abs(second.row - first.row), abs(second.col - first.col)) > 4
    policy.reset()  # a new episode forgets
    assert decode_action(prims, policy.act(obs)) == first
    env.close()


def encode(prims, a):
    from mpg_envs.grid.actions import encode_action

    return encode_action(prims, a.primitive, a.rotation, a.row, a.col)


def test_shipped_grasps_land_where_the_fingers_are_least_blocked():
    import gymnasium as gym
    import numpy as np
    import torch

    from mpg_agents.evaluation.policy_zoo import make_policy
    from mpg_agents.network.regions import least_blocked, target_pixels
    from mpg_envs.grid.actions import decode_action
    from mpg_envs.grid.grasp_geometry import fingers_blocked

    env = gym.make("MPG-Occluded-v0", num_objects=15)
    # Grasp-first at Q*_g 0: a grasp whenever the target shows, so the first action is a grasp.
    policy = make_policy("shipped", env, coordination="grasp_first", q_star=0.0)
    assert policy.policy.net_config.grasp_fingers == "clear"
    obs, _ = env.reset(seed=700_003)
    a = decode_action(env.unwrapped.primitives, policy.act(obs))
    assert a.primitive == "grasp"
    blocked = torch.from_numpy(fingers_blocked(np.asarray(obs["depth"]), 0.002, 0.04, 0.02))[None]
    on_target = target_pixels(torch.from_numpy(obs["mask"][None] > 0), -8)
    kept = least_blocked(blocked, on_target, 0.005)[0] & on_target[0][None]
    assert kept[a.rotation, a.row, a.col] and kept.sum() < on_target.sum() * 16
    env.close()
