"""The getting-started page's real-camera recipe on rendered frames: one camera's RGB-D frame of
a clutter and one of the object alone on the empty table (the cameras of camera mode stand in for
a real one) -> heightmaps -> an exemplar-mode observation -> an action of the shipped net through
a locator."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_agents.evaluation.policy_zoo import make_policy
from mpg_agents.locator.features import centred_query
from mpg_agents.locator.locator import save_locator
from mpg_agents.locator.net import LocatorConfig, LocatorNet
from mpg_envs.perception.camera import CameraConfig, CameraHeightmapper
from mpg_envs.perception.rgbd import heightmap_from_rgbd


def _frame(env_id: str, num_objects: int, seed: int):
    """One camera's frame (colour, depth, K, camera pose) of a camera-mode scene."""
    env = gym.make(env_id, obs_mode="camera", num_objects=num_objects)
    try:
        env.reset(seed=seed)
        world = env.unwrapped.world
        with CameraHeightmapper(world.model, CameraConfig()) as cameras:
            image = cameras.render(world.data)[0]
        return image.color, image.depth, image.intrinsics, image.pose
    finally:
        env.close()


def test_a_camera_frame_and_a_photo_of_the_object_give_an_action(tmp_path: Path):
    color, depth, K, cam_pose = _frame("MPG-Stage4-v0", 8, 3)
    object_color, object_depth, _, _ = _frame("MPG-Stage2-v0", 1, 4)  # an object alone, through the same camera
    scene = heightmap_from_rgbd(color, depth, K, cam_pose)
    alone = heightmap_from_rgbd(object_color, object_depth, K, cam_pose)
    query_color, query_depth = centred_query(alone.color, alone.depth)
    obs = {
        "color": scene.color,
        "depth": scene.depth.astype(np.float32),
        "query_color": query_color,
        "query_depth": query_depth,
    }
    locator = tmp_path / "locator.safetensors"
    save_locator(LocatorNet(LocatorConfig(8, 8, 16)), locator, 0.5, 0.5, {})
    env = gym.make("MPG-OccludedHardExemplar-v0")  # for its observation and action spaces
    policy = make_policy("shipped", env, locator=locator, device="cpu")
    assert env.observation_space.contains(obs)
    primitive, rotation, row, col = env.unwrapped.action_space.decode(policy.act(obs))
    assert primitive in ("move", "push", "grasp") and 0 <= row < 224 and 0 <= col < 224 and 0 <= rotation < 16
    rows, cols = np.nonzero(query_depth > 0.002)
    assert abs((rows.min() + rows.max()) / 2 - 112) <= 1 and abs((cols.min() + cols.max()) / 2 - 112) <= 1
