"""Camera observations: one colour convention with the ray-cast heightmaps, and the seeded
visual randomization. Tests marked ``gl`` are skipped (with the reason) without OpenGL."""

from __future__ import annotations

import os

# MuJoCo picks its GL backend when it is first imported.
os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from mpg_envs.perception.camera import CameraConfig  # noqa: E402
from mpg_envs.perception.heightmap import RaycastHeightmapper  # noqa: E402

from .hand_scenes import make_cameras  # noqa: E402




@pytest.mark.gl
def test_camera_colours_follow_the_raycast_convention(record_property):
    """On a dropped scene the camera heightmap's colours are the ray-cast heightmap's: mean
    absolute difference over object pixels (RGB, 0-255) under 3. Measured 0.6-1.3 on four
    hard-track scenes (the rest is edge pixels where the two paths see different surfaces),
    against 57-66 under the arena's lights before the camera path had its own light."""
    from mpg_envs.tasks.env import MPGEnv

    env = MPGEnv("Stage5", num_objects=10, obs_mode="camera")
    try:
        obs, _ = env.reset(seed=3)
    except RuntimeError as exc:
        pytest.skip(f"no OpenGL context for camera observations: {exc}")
    with RaycastHeightmapper(env.world.model) as mapper:
        truth = mapper(env.world.data)
    env.close()
    objects = (truth.depth > 0.005) & (obs["depth"] > 0.005)
    assert objects.sum() > 2000
    mad = float(np.abs(obs["color"].astype(int) - truth.color.astype(int))[objects].mean())
    record_property("object_colour_mad", round(mad, 3))
    assert mad < 3.0, f"camera and ray-cast colours differ by {mad:.2f} on average over object pixels"


@pytest.mark.gl
def test_randomized_views_are_fixed_by_the_seed(clutter):
    from mpg_envs.perception.visual_randomization import VisualRandomization, draw_visuals

    model, data, _ = clutter
    no_noise = VisualRandomization(depth_noise=None)
    with make_cameras(model, CameraConfig()) as cams:
        clean = cams(data)
        a = cams(data, visuals=draw_visuals(no_noise, 5))
        b = cams(data, visuals=draw_visuals(no_noise, 5))
        noisy = cams(data, rng=np.random.default_rng(0), visuals=draw_visuals(VisualRandomization(), 5))
        with pytest.raises(ValueError, match="Generator"):
            cams(data, visuals=draw_visuals(VisualRandomization(), 5))
    np.testing.assert_array_equal(a.color, b.color)
    np.testing.assert_array_equal(a.depth, b.depth)
    assert not np.array_equal(a.color, clean.color)
    occupied = clean.depth > 0.005
    # A calibration error of up to 1 cm / 1 degree moves the heights a little, not a lot.
    shift = np.abs(a.depth - clean.depth)[occupied]
    assert 0 < float(np.median(shift)) < 0.01
    # The sensor's holes: more pixels that no camera sees (background colour, no geom).
    assert (noisy.geom_id == -1).sum() > (a.geom_id == -1).sum() + 100


@pytest.mark.gl
def test_one_pass_depth_and_segmentation_match_mujocos_renderer(clutter):
    """``SceneFrames`` reads depth and segmentation from one pass; ``mujoco.Renderer`` renders
    them apart: the two agree exactly."""
    from mpg_envs.perception.frames import SceneFrames

    model, data, names = clutter
    cam_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, names[0])
    try:
        frames = SceneFrames(model, 240, 320)
        renderer = mujoco.Renderer(model, 240, 320)
    except RuntimeError as exc:
        pytest.skip(f"no OpenGL context: {exc}")
    frames.update(data, cam_id, mujoco.MjvOption())
    depth, geom_id = frames.depth_and_segmentation()
    renderer.update_scene(data, camera=cam_id)
    renderer.enable_depth_rendering()
    expected_depth = renderer.render()
    renderer.enable_segmentation_rendering()
    seg = renderer.render()
    renderer.close()
    frames.close()
    np.testing.assert_array_equal(depth, expected_depth)
    np.testing.assert_array_equal(geom_id, np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1))
    assert (geom_id >= 0).mean() > 0.9


@pytest.mark.gl
def test_the_occlusion_flag_on_camera_images_is_the_ray_cast_tracks():
    """With a calibration error the camera's heightmap sits up to about 1 cm off the target's
    true footprint; the flag is judged on a clean top-down view of the same state, so a clear
    target is not flagged covered (seed 700009 was: a neighbour's rim inside the footprint)."""
    import gymnasium as gym

    import mpg_envs  # noqa: F401  (registers the ids)

    seeds = (700000, 700004, 700009)
    plain = gym.make("MPG-Stage5-v0")
    expected = [int(plain.reset(seed=s)[0]["occluded"][0]) for s in seeds]
    plain.close()
    # The seeds' drops settle per MuJoCo major version (seed 700004's target lands covered on 4):
    # the scenes the flags are compared on, with a clear target among them.
    assert expected == {3: [1, 0, 0], 4: [1, 1, 0]}[int(mujoco.__version__.split(".")[0])]
    camera = gym.make("MPG-Stage5-v0", obs_mode="camera", visual_randomization=True)
    try:
        flags = [int(camera.reset(seed=s)[0]["occluded"][0]) for s in seeds]
    except RuntimeError as exc:
        pytest.skip(f"no OpenGL context for camera observations: {exc}")
    finally:
        camera.close()
    assert flags == expected
