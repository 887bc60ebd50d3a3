"""mpg_envs.integrations.wrappers: the image/action maths on hand-checked cases, then the wrappers on real
envs through Gymnasium's and SB3's checkers (small scenes keep resets quick)."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_envs.grid.actions import decode_action
from mpg_envs.integrations.wrappers import (
    ContinuousAction,
    GridAction,
    ImageObservation,
    continuous_to_pixel_action,
    grid_rotation,
    grid_to_pixel_action,
    image_from_observation,
    quantise_depth,
)


# ----------------------------------------------------------------------------- pure maths
def test_quantise_depth_scale_and_errors():
    out = quantise_depth(np.array([0.0, 0.4 / 255, 0.2, 0.4], np.float32), z_max=0.4)
    assert out.dtype == np.uint8 and out.tolist() == [0, 1, 128, 255]  # 0.2 m = 127.5 -> 128
    with pytest.raises(ValueError, match=r"depth must lie in \[0, 0.4\]"):
        quantise_depth(np.array([0.5]), 0.4)
    with pytest.raises(ValueError, match="depth must lie"):
        quantise_depth(np.array([-0.01]), 0.4)


def _obs(size=4, occluded=0):
    color = np.zeros((size, size, 3), np.uint8)
    color[0, 0] = (10, 20, 30)
    depth = np.zeros((size, size), np.float32)
    depth[1, 2] = 0.4
    mask = np.zeros((size, size), np.uint8)
    mask[3, 3] = 1
    return {"color": color, "depth": depth, "mask": mask, "occluded": np.array([occluded], np.int8)}


def test_image_planes_channels_first_and_last():
    image = image_from_observation(_obs(), size=4, z_max=0.4)
    assert image.shape == (5, 4, 4) and image.dtype == np.uint8
    assert image[:3, 0, 0].tolist() == [10, 20, 30]
    assert image[3, 1, 2] == 255 and image[3].sum() == 255
    assert image[4, 3, 3] == 255 and image[4].sum() == 255
    last = image_from_observation(_obs(), size=4, z_max=0.4, channels_last=True)
    np.testing.assert_array_equal(last, image.transpose(1, 2, 0))


def test_image_resize_averages_colour_keeps_mask_binary_and_occlusion_plane():
    obs = _obs(size=8, occluded=1)
    obs["color"][:] = 0
    obs["color"][:2, :2] = 200  # one 2x2 block -> one output pixel of a 4x4 image
    obs["mask"][:] = 0
    obs["mask"][4:, 4:] = 1
    image = image_from_observation(obs, size=4, z_max=0.4, occlusion_channel=True)
    assert image.shape == (6, 4, 4)
    assert image[0, 0, 0] == 200 and image[0].sum() == 200
    assert set(np.unique(image[4]).tolist()) == {0, 255}
    assert image[4, 2:, 2:].min() == 255 and image[4, :2].max() == 0
    assert (image[5] == 255).all()


def test_grid_rotation_symmetric_primitives_span_180_push_360():
    assert [grid_rotation("grasp", r, 8) for r in range(8)] == list(range(8))
    assert [grid_rotation("move", r, 4) for r in range(4)] == [0, 2, 4, 6]
    assert [grid_rotation("push", r, 8) for r in range(8)] == [0, 2, 4, 6, 8, 10, 12, 14]
    assert [grid_rotation("grasp", r, 16) for r in range(16)] == list(range(16))


def test_grid_index_decodes_to_cell_centres():
    prims = ("push", "grasp")
    # cells of 8 on 224: 28 x 28; index = ((p * R + r) * 28 + cell_row) * 28 + cell_col
    index = ((1 * 8 + 3) * 28 + 2) * 28 + 27
    assert tuple(grid_to_pixel_action(index, prims, 8, 8, 224)) == ("grasp", 3, 20, 220)
    assert tuple(grid_to_pixel_action(0, prims, 8, 8, 224)) == ("push", 0, 4, 4)
    assert tuple(grid_to_pixel_action(np.int64(1 * 28 * 28), prims, 8, 8, 224)) == ("push", 2, 4, 4)
    with pytest.raises(ValueError, match=r"action must be an integer in 0\.\.12543"):
        grid_to_pixel_action(2 * 8 * 28 * 28, prims, 8, 8, 224)
    with pytest.raises(ValueError, match="action must be an integer"):
        grid_to_pixel_action(1.5, prims, 8, 8, 224)


def test_continuous_action_mapping():
    prims = ("move", "push", "grasp")
    assert tuple(continuous_to_pixel_action(np.array([-1, -1, -1, 0, 0, 1]), prims, 224)) == ("grasp", 0, 0, 0)
    assert tuple(continuous_to_pixel_action(np.array([1, 1, 1, 0.5, 0, 0]), prims, 224)) == ("move", 0, 223, 223)
    # x = 0 is the boundary between pixels 111 and 112: the bin starting there; angle 0 = 180 deg
    assert tuple(continuous_to_pixel_action(np.array([0, -0.5, 0, 0, 1, 0]), prims, 224)) == ("push", 8, 56, 112)
    assert continuous_to_pixel_action(np.array([0, 0, -1 + 1 / 8, 0, 0, 1]), prims, 224).rotation == 1  # 22.5 deg
    assert continuous_to_pixel_action(np.array([0, 0, 0, 1, 1, 0]), prims, 224).primitive == "move"  # tie: first
    with pytest.raises(ValueError, match=r"finite and in \[-1, 1\]"):
        continuous_to_pixel_action(np.array([1.5, 0, 0, 0, 0, 0]), prims, 224)
    with pytest.raises(ValueError, match=r"shape \(6,\)"):
        continuous_to_pixel_action(np.zeros(4), prims, 224)


# ----------------------------------------------------------------------------- on the envs
@pytest.fixture(scope="module")
def stage2():
    env = gym.make("MPG-Stage2-v0", num_objects=1)
    yield env
    env.close()


def test_bad_grid_arguments_name_the_valid_values(stage2):
    with pytest.raises(ValueError, match=r"cell must .* one of \[1, 2, 4, 7, 8, 14, 16, 28, 32, 56, 112, 224\]; got 5"):
        GridAction(stage2, cell=5)
    with pytest.raises(ValueError, match=r"rotations must divide .* one of \[1, 2, 4, 8, 16\]; got 3"):
        GridAction(stage2, rotations=3)
    with pytest.raises(ValueError, match="size must be an integer"):
        ImageObservation(stage2, size=0)
    with pytest.raises(ValueError, match="needs the MPG Dict observation"):
        ImageObservation(ImageObservation(stage2))


def test_spaces_and_sizes():
    env = gym.make("MPG-Stage5-v0")
    assert GridAction(env).action_space == gym.spaces.Discrete(3 * 8 * 28 * 28)
    assert GridAction(env, cell=16, rotations=4).action_space == gym.spaces.Discrete(3 * 4 * 14 * 14)
    assert ContinuousAction(env).action_space == gym.spaces.Box(-1, 1, (6,), np.float32)
    assert ImageObservation(env).observation_space == gym.spaces.Box(0, 255, (5, 84, 84), np.uint8)
    assert ImageObservation(env, size=224, channels_last=True).observation_space.shape == (224, 224, 5)
    env.close()


class _KeepObservation(gym.Wrapper):
    """Keeps the raw observation the wrapper above it turns into an image."""

    def step(self, action):
        result = self.env.step(action)
        self.last = result[0]
        return result


def test_grid_action_acts_at_the_cell_centre(stage2):
    keep = _KeepObservation(GridAction(stage2))
    env = ImageObservation(keep, size=224)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs) and "occluded" in info
    index = (5 * 28 + 10) * 28 + 3  # grasp, rotation 5, cell (10, 3)
    obs, _, _, _, info = env.step(index)
    assert (info["primitive"], info["rotation"], info["pixel"]) == ("grasp", 5, (84, 28))
    # The image is the Dict observation's planes, unresized at 224.
    raw = keep.last
    np.testing.assert_array_equal(obs[:3], raw["color"].transpose(2, 0, 1))
    np.testing.assert_array_equal(obs[4], raw["mask"] * 255)


def test_continuous_action_encodes_the_env_index():
    env = ContinuousAction(gym.make("MPG-Stage5-v0"))
    a = np.array([0.0, -0.5, 0.0, 0.1, 0.9, 0.2], np.float32)
    flat = env.action(a)
    assert tuple(decode_action(("move", "push", "grasp"), flat)) == ("push", 8, 56, 112)
    env.close()


def _checks_without_warnings(env, sb3: bool) -> None:
    from gymnasium.utils.env_checker import check_env as gym_check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # Gymnasium always says this of a wrapped env; checking the wrapper is the point here.
        warnings.filterwarnings("ignore", message=".*is different from the unwrapped version")
        gym_check_env(env, skip_render_check=True)
        if sb3:
            sb3_check_env(env)


def test_image_grid_passes_both_checkers(stage2):
    # SB3's checker on GridAction alone would only repeat its warning about the raw Dict obs.
    _checks_without_warnings(ImageObservation(GridAction(stage2, cell=16, rotations=4)), sb3=True)


def test_image_continuous_passes_both_checkers():
    env = gym.make("MPG-Stage5-v0", num_objects=2)
    _checks_without_warnings(ImageObservation(ContinuousAction(env), size=64, channels_last=True, occlusion_channel=True), sb3=True)
    env.close()


def test_image_on_raw_actions_passes_sb3_checker(stage2):
    _checks_without_warnings(ImageObservation(stage2), sb3=True)


def test_sb3_ppo_cnn_policy_under_5m_parameters():
    from stable_baselines3 import PPO

    env = ImageObservation(GridAction(gym.make("MPG-Stage2-v0")))
    model = PPO("CnnPolicy", env, n_steps=16, batch_size=16, device="cpu")
    count = sum(p.numel() for p in model.policy.parameters())
    print(f"PPO CnnPolicy on MPG-Stage2-v0: {count:,} parameters")
    assert count < 5_000_000
    env.close()


# ----------------------------------------------------------------------------- vector envs
def _threads_in_a_child() -> int:
    import concurrent.futures
    import multiprocessing

    from mpg_envs.perception.heightmap import _default_threads

    with concurrent.futures.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(_default_threads).result(timeout=120)


def test_vector_env_workers_ray_cast_on_one_thread_unless_asked(monkeypatch):
    # AsyncVectorEnv/SubprocVecEnv workers are multiprocessing children: 2 workers x 2 ray-cast
    # threads would oversubscribe 2 cores (issue 11.4).
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.delenv("MPG_NUM_THREADS", raising=False)
    assert _threads_in_a_child() == 1
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    assert _threads_in_a_child() == 2
