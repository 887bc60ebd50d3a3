"""Visual randomization and the depth sensor model: pure image maths on hand-checked cases,
per-seed draws, and the env option on the ray-cast path (no OpenGL here; the camera path's
checks are in ``test_camera.py``)."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_envs.perception.appearance import Lighting, perturbed_pose
from mpg_envs.perception.depth_noise import (
    DepthNoise,
    corrupt_depth,
    corrupt_heights,
    dark_pixels,
    depth_edges,
    depth_noise_std,
)
from mpg_envs.perception.visual_randomization import (
    CAMERA_SLOTS,
    VisualRandomization,
    draw_visuals,
    jitter_colors,
    randomized_geom_colors,
)
from mpg_envs.perception.camera import CameraConfig
from mpg_envs.perception.misregistration import misregistered_heightmaps
from mpg_envs.tasks.env import MPGEnv
from mpg_envs.tasks.tracks import TRACKS

CLEAN = DepthNoise(base_std=0.0, quadratic=0.0, edge_dropout=0.0, dark_dropout=0.0, random_dropout=0.0)


# ----------------------------------------------------------------------------------------
# Depth sensor model (pure)
# ----------------------------------------------------------------------------------------


def test_depth_noise_std_hand_checked():
    noise = DepthNoise(base_std=0.0005, quadratic=0.0015)
    # 0.0005 + 0.0015 * z^2: 0.002 at 1 m, 0.0065 at 2 m, the base at 0.
    np.testing.assert_allclose(depth_noise_std(np.array([0.0, 1.0, 2.0]), noise), [0.0005, 0.002, 0.0065])


def test_depth_edges_hand_checked():
    depth = np.full((5, 5), 0.6)
    depth[2, 2] = 0.5  # a 10 cm step at the centre
    depth[0, 4] = 0.0  # no depth in a corner
    edges = depth_edges(depth, jump=0.05)
    expected = np.zeros((5, 5), bool)
    expected[2, 2] = expected[1, 2] = expected[3, 2] = expected[2, 1] = expected[2, 3] = True
    expected[0, 3] = expected[1, 4] = True  # beside the pixel without depth
    np.testing.assert_array_equal(edges, expected)
    assert not depth_edges(depth, jump=0.2)[2, 2]  # a step smaller than the jump is no edge


def test_dark_pixels_use_luma():
    color = np.array([[[10, 10, 10], [100, 100, 100], [255, 0, 0], [0, 0, 200]]], np.uint8)
    # Luma: 10, 100, 76.2, 22.8.
    np.testing.assert_array_equal(dark_pixels(color, 25.0), [[True, False, False, True]])
    np.testing.assert_array_equal(dark_pixels(color, 80.0), [[True, False, True, True]])


def test_corrupt_depth_clean_noisy_and_holes():
    rng = np.random.default_rng(0)
    depth = np.full((200, 200), 1.0)
    depth[:, :5] = 0.0  # no reading there
    color = np.full((200, 200, 3), 128, np.uint8)
    np.testing.assert_array_equal(corrupt_depth(depth, color, CLEAN, rng), depth.astype(np.float32))

    noisy = corrupt_depth(depth, color, DepthNoise(random_dropout=0.0, edge_dropout=0.0), rng)
    inner = noisy[:, 10:]
    assert np.std(inner - 1.0) == pytest.approx(0.002, rel=0.05)  # 0.0005 + 0.0015 * 1^2
    assert np.all(noisy[:, :5] == 0)  # no depth stays no depth

    holes = corrupt_depth(depth, color, DepthNoise(base_std=0.0, quadratic=0.0, edge_dropout=1.0, random_dropout=0.0), rng)
    assert np.all(holes[:, 5] == 0) and np.all(holes[:, 6:] == 1.0)  # the edge beside the missing band is lost

    dark = color.copy()
    dark[100:] = 5
    lost = corrupt_depth(depth, dark, DepthNoise(base_std=0.0, quadratic=0.0, dark_dropout=1.0, edge_dropout=0.0, random_dropout=0.0), rng)
    assert np.all(lost[100:] == 0) and np.all(lost[:100, 5:] == 1.0)


def test_corrupt_heights_as_an_overhead_camera():
    rng = np.random.default_rng(1)
    heights = np.zeros((100, 100))
    heights[40:60, 40:60] = 0.05
    color = np.full((100, 100, 3), 128, np.uint8)
    out, lost = corrupt_heights(heights, color, CLEAN, rng, camera_height=0.85, max_height=0.4)
    np.testing.assert_array_equal(out, heights.astype(np.float32))
    assert not lost.any()
    edge_only = DepthNoise(base_std=0.0, quadratic=0.0, edge_dropout=1.0, random_dropout=0.0)
    out, lost = corrupt_heights(heights, color, edge_only, rng, camera_height=0.85, max_height=0.4)
    # The 20 x 20 block's rim (80 - 4 corners counted twice = 76 px) and the ring of 4-neighbours outside it (80 px).
    assert lost.sum() == 76 + 80
    assert np.all(out[lost] == 0)
    with pytest.raises(ValueError, match="camera_height"):
        corrupt_heights(heights, color, CLEAN, rng, camera_height=0.3, max_height=0.4)


def test_depth_noise_validation():
    with pytest.raises(ValueError, match="edge_dropout"):
        DepthNoise(edge_dropout=1.5)
    with pytest.raises(ValueError, match="base_std"):
        DepthNoise(base_std=-1.0)


# ----------------------------------------------------------------------------------------
# Colours, poses and draws (pure)
# ----------------------------------------------------------------------------------------


def test_jitter_colors_hand_checked():
    rgb = np.array([[100, 200, 250], [0, 10, 255]], np.uint8)
    out = jitter_colors(rgb, np.array([[1.1, 1.0, 1.1], [2.0, 0.45, 0.5]]))
    # 110, 200, 275 -> 255; 0, 4.5 -> 4 (round half to even), 127.5 -> 128.
    np.testing.assert_array_equal(out, [[110, 200, 255], [0, 4, 128]])
    with pytest.raises(ValueError, match="uint8"):
        jitter_colors(rgb.astype(float), 1.0)


def test_perturbed_pose_hand_checked():
    pos, xmat = perturbed_pose([0.5, 0.0, 1.0], np.eye(3), [0.01, 0.0, 0.0], [0.0, 0.0, np.pi / 2])
    np.testing.assert_allclose(pos, [0.51, 0.0, 1.0])
    np.testing.assert_allclose(xmat, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)


def test_lighting_validation():
    with pytest.raises(ValueError, match="point down"):
        Lighting(direction=(0.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="ambient"):
        Lighting(ambient=-0.1)


def test_draws_are_fixed_by_the_seed_and_inside_the_ranges():
    config = VisualRandomization()
    a, b, c = draw_visuals(config, 7), draw_visuals(config, 7), draw_visuals(config, 8)
    assert a.to_dict() == b.to_dict() and a.to_dict() != c.to_dict()
    for seed in range(50):
        v = draw_visuals(config, seed)
        d = np.asarray(v.lighting.direction)
        assert np.degrees(np.arccos(-d[2] / np.linalg.norm(d))) <= config.light_tilt + 1e-9
        assert 0.85 <= v.lighting.ambient + v.lighting.diffuse <= 1.15
        assert v.camera_offsets.shape == (CAMERA_SLOTS, 3)
        assert np.all(np.linalg.norm(v.camera_offsets, axis=1) <= 0.01 + 1e-12)
        assert np.all(np.degrees(np.linalg.norm(v.camera_rotations, axis=1)) <= 1.0 + 1e-9)
        assert np.all((v.object_gains > 0.85 * 0.9 - 1e-9) & (v.object_gains < 1.15 * 1.1 + 1e-9))
        assert 0.00025 <= v.depth_noise.base_std <= 0.00075


def test_option_values():
    assert VisualRandomization.from_option(None) is None and VisualRandomization.from_option(False) is None
    assert VisualRandomization.from_option(True) == VisualRandomization()
    custom = VisualRandomization.from_option({"light_tilt": 10.0, "depth_noise": None, "ambient_share": [0.5, 0.5]})
    assert custom.light_tilt == 10.0 and custom.depth_noise is None and custom.ambient_share == (0.5, 0.5)
    assert VisualRandomization.from_option({"depth_noise": {"edge_dropout": 0.2}}).depth_noise.edge_dropout == 0.2
    with pytest.raises(ValueError, match="unknown VisualRandomization fields"):
        VisualRandomization.from_option({"light": 1})
    with pytest.raises(ValueError, match="visual_randomization must be"):
        VisualRandomization.from_option("yes")
    with pytest.raises(ValueError, match="light_tilt"):
        VisualRandomization(light_tilt=95.0)


def test_randomized_geom_colors_per_body():
    spec = mujoco.MjSpec()
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.5, 0.5, 0.05], rgba=[0.4, 0.4, 0.4, 1], group=0)
    for k, rgba in enumerate(([0.2, 0.4, 0.6, 1], [0.8, 0.2, 0.2, 1])):
        body = spec.worldbody.add_body(pos=[0.1 * k, 0, 0.1])
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.02] * 3, rgba=rgba, group=1)
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0, 0], pos=[0, 0, 0.03], rgba=rgba, group=1)
    model = spec.compile()
    visuals = draw_visuals(VisualRandomization(), 3)
    colors = randomized_geom_colors(model, visuals)
    base = np.round(np.array([[0.4] * 3, [0.2, 0.4, 0.6], [0.2, 0.4, 0.6], [0.8, 0.2, 0.2], [0.8, 0.2, 0.2]]) * 255).astype(np.uint8)
    np.testing.assert_array_equal(colors[0], jitter_colors(base[0], visuals.table_gain))
    np.testing.assert_array_equal(colors[1:3], jitter_colors(base[1:3], visuals.object_gains[0]))  # one body, one colour
    np.testing.assert_array_equal(colors[3:5], jitter_colors(base[3:5], visuals.object_gains[1]))
    np.testing.assert_array_equal(randomized_geom_colors(model, None), base)


# ----------------------------------------------------------------------------------------
# The env option (ray-cast path) and the track's registration
# ----------------------------------------------------------------------------------------


def test_env_option_on_the_raycast_path():
    plain = MPGEnv("Stage2", num_objects=3)
    noisy = MPGEnv("Stage2", num_objects=3, visual_randomization=True)
    obs0, info0 = plain.reset(seed=4)
    obs1, info1 = noisy.reset(seed=4)
    # The scene is the seed's, with or without randomization.
    np.testing.assert_array_equal(plain.world.data.qpos, noisy.world.data.qpos)
    assert "visual_randomization" not in info0
    drawn = info1["visual_randomization"]
    assert drawn["seed"] == 4 and len(drawn["object_gains"]) == 3
    assert not np.array_equal(obs0["color"], obs1["color"]) and not np.array_equal(obs0["depth"], obs1["depth"])
    obs2, info2 = noisy.reset(seed=4)
    assert info2["visual_randomization"] == drawn
    for key in ("color", "depth", "mask"):
        np.testing.assert_array_equal(obs1[key], obs2[key])
    # A step tried and undone sees the noise the step then sees.
    action = noisy.action_space.encode("grasp", 0, 112, 112)
    tried = noisy.try_step(action)[0]
    taken = noisy.step(action)[0]
    np.testing.assert_array_equal(tried["depth"], taken["depth"])
    plain.close()
    noisy.close()


def test_misregistration_on_the_raycast_path_places_the_view_as_the_cameras_would():
    options = {"depth_noise": None, "object_brightness": 0.0, "object_hue": 0.0, "table_brightness": 0.0, "table_hue": 0.0}
    registered = MPGEnv("Stage5", num_objects=8, visual_randomization=options)
    moved = MPGEnv("Stage5", num_objects=8, visual_randomization={**options, "raycast_misregistration": True})
    obs0, info0 = registered.reset(seed=11)
    obs1, info1 = moved.reset(seed=11)
    assert "raycast_misregistration" not in info0["visual_randomization"] and info1["visual_randomization"]["raycast_misregistration"]
    # Colour and depth are the registered view moved by the cameras' errors; mask and flag are the true state's.
    centres = np.array([cam.position for cam in CameraConfig().cameras])
    visuals = moved.sim.visuals
    expected = misregistered_heightmaps(
        registered.sim.heightmaps(), moved.sim.config.workspace, centres, visuals.camera_offsets[:2], visuals.camera_rotations[:2]
    )
    np.testing.assert_array_equal(obs1["color"], expected.color)
    np.testing.assert_array_equal(obs1["depth"], expected.depth)
    assert not np.array_equal(obs1["depth"], obs0["depth"])
    np.testing.assert_array_equal(obs1["mask"], obs0["mask"])
    np.testing.assert_array_equal(obs1["occluded"], obs0["occluded"])
    with pytest.raises(ValueError, match="raycast_misregistration must be True or False"):
        VisualRandomization(raycast_misregistration=1)
    registered.close()
    moved.close()


def test_camera_track_is_registered():
    track = TRACKS["MPG-OccludedHardCamera-v0"]
    spec = gym.spec(track.env_id)
    assert spec.kwargs == {"stage": "OccludedHard", "obs_mode": "camera", "visual_randomization": True}
    assert spec.max_episode_steps == 10
    env = gym.make(track.env_id).unwrapped  # making it renders nothing yet
    assert env.stage.name == "OccludedHard" and env.obs_mode == "camera" and env.wrong_grasp == "fail"
    assert env.visual_randomization == VisualRandomization()
    env.close()
