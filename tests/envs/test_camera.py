"""Camera observation mode: fixed RGB-D cameras back-projected into heightmaps.

Tests marked ``gl`` need an OpenGL context; they are skipped (with the reason) when
``mujoco.Renderer`` cannot create one.
"""

from __future__ import annotations

import os

# MuJoCo picks its GL backend when it is first imported.
os.environ.setdefault("MUJOCO_GL", "egl")

import math  # noqa: E402

import cv2  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import mpg_envs.perception.render as render_module  # noqa: E402
from mpg_envs.perception.camera import (  # noqa: E402
    CameraConfig,
    CameraHeightmapper,
    FixedCamera,
    add_cameras,
    camera_intrinsics,
    look_at_xmat,
    opencv_camera_pose,
)
from mpg_envs.perception.heightmap import RaycastHeightmapper  # noqa: E402
from mpg_envs.grid.workspace import Workspace  # noqa: E402

from .hand_scenes import BOX, clutter_spec, compile_forward, make_cameras, yaw_quat  # noqa: E402

WS = Workspace()


# ----------------------------------------------------------------------------------------
# Pure camera geometry (no GL)
# ----------------------------------------------------------------------------------------


def test_camera_intrinsics_hand_checked():
    # fovy 90 deg over 480 rows: f = 240 / tan(45 deg) = 240; OpenCV pixel centres are at
    # integers, so the principal point is (639 / 2, 479 / 2).
    np.testing.assert_allclose(
        camera_intrinsics(90.0, 640, 480), [[240, 0, 319.5], [0, 240, 239.5], [0, 0, 1]], atol=1e-9
    )
    with pytest.raises(ValueError, match="fovy"):
        camera_intrinsics(180.0, 640, 480)


def test_look_at_and_opencv_pose():
    position, target = np.array([1.15, 0.0, 0.62]), np.array([0.5, 0.0, 0.0])
    xmat = look_at_xmat(position, target)
    np.testing.assert_allclose(xmat @ xmat.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(xmat) == pytest.approx(1.0)
    forward = (target - position) / np.linalg.norm(target - position)
    np.testing.assert_allclose(-xmat[:, 2], forward, atol=1e-12)  # MuJoCo cameras look along -z
    assert abs(xmat[2, 0]) < 1e-12  # image x axis horizontal

    # Straight down: image up (+y) is world +x, image right is world -y.
    down = look_at_xmat(np.array([0.5, 0.0, 1.0]), np.array([0.5, 0.0, 0.0]))
    np.testing.assert_allclose(down, [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=1e-12)
    pose = opencv_camera_pose([0.5, 0.0, 1.0], down.ravel())
    # OpenCV frame: x right (world -y), y down (world -x), z forward (world -z).
    np.testing.assert_allclose(pose[:3, :3], [[0, -1, 0], [-1, 0, 0], [0, 0, -1]], atol=1e-12)
    np.testing.assert_allclose(pose[:3, 3], [0.5, 0.0, 1.0])
    np.testing.assert_allclose(pose[3], [0, 0, 0, 1])


def test_default_cameras_see_the_whole_workspace():
    """Every corner of the workspace box up to 10 cm above the table projects into every
    default camera's image (pure geometry: our K and pose, no rendering)."""
    config = CameraConfig()
    k = camera_intrinsics(config.fovy, config.width, config.height)
    corners = np.array(
        [[x, y, z] for x in (WS.x_min, WS.x_max) for y in (WS.y_min, WS.y_max) for z in (0.0, 0.1)]
    )
    for cam in config.cameras:
        xmat = look_at_xmat(np.array(cam.position), np.array(cam.target))
        pose = opencv_camera_pose(cam.position, xmat.ravel())
        local = (corners - pose[:3, 3]) @ pose[:3, :3]  # world -> OpenCV camera frame
        assert np.all(local[:, 2] > 0), cam.name
        uv = (local @ k.T)[:, :2] / local[:, 2:3]
        assert np.all((uv >= 0) & (uv <= [config.width - 1, config.height - 1])), (cam.name, uv)


def test_add_cameras_to_spec():
    spec = clutter_spec()
    config = CameraConfig(width=800, height=600)
    names = add_cameras(spec, config)
    assert names == ["mpg_cam_overhead", "mpg_cam_front"]
    model, data = compile_forward(spec)
    assert model.vis.global_.offwidth >= 800 and model.vis.global_.offheight >= 600
    for cam in config.cameras:
        cam_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, cam.name)
        assert cam_id >= 0 and model.cam_fovy[cam_id] == pytest.approx(config.fovy)
        np.testing.assert_allclose(data.cam_xpos[cam_id], cam.position, atol=1e-9)
        np.testing.assert_allclose(
            data.cam_xmat[cam_id].reshape(3, 3),
            look_at_xmat(np.array(cam.position), np.array(cam.target)),
            atol=1e-9,
        )
    with pytest.raises(ValueError, match="already has a camera"):
        add_cameras(spec, config)


def test_camera_config_validation():
    with pytest.raises(ValueError, match="unique"):
        CameraConfig(cameras=(FixedCamera("a", (0.5, 0, 1)), FixedCamera("a", (0.6, 0, 1))))
    with pytest.raises(ValueError, match="depth_noise_std"):
        CameraConfig(depth_noise_std=-0.001)
    with pytest.raises(ValueError, match="near"):
        CameraConfig(near=2.0, far=1.0)
    with pytest.raises(ValueError, match="target"):
        FixedCamera("a", (0.5, 0.0, 0.0), (0.5, 0.0, 0.0))


def test_missing_camera_is_reported():
    model, _ = compile_forward(clutter_spec())
    with pytest.raises(ValueError, match="add_cameras"):
        CameraHeightmapper(model, CameraConfig())


def test_gl_failure_names_the_fix(monkeypatch):
    spec = clutter_spec()
    add_cameras(spec)
    model, _ = compile_forward(spec)

    def no_gl(*args, **kwargs):
        raise mujoco.FatalError("gladLoadGL error")

    monkeypatch.setattr(mujoco, "GLContext", no_gl)  # the camera path's frames open their context with it
    monkeypatch.setattr(render_module, "_gl_failure", None)  # as in a fresh process
    with pytest.raises(RuntimeError) as info:
        CameraHeightmapper(model, CameraConfig())
    message = str(info.value)
    for needle in ("MUJOCO_GL", "libegl1", "libegl-mesa0", "libgl1-mesa-dri", "libosmesa6", "gladLoadGL"):
        assert needle in message

    # A second attempt fails the same way without touching GL again (a retry can abort
    # the process with some backends).
    def must_not_run(*args, **kwargs):
        raise AssertionError("GL was retried")

    monkeypatch.setattr(mujoco, "GLContext", must_not_run)
    monkeypatch.setattr(mujoco, "Renderer", must_not_run)
    with pytest.raises(RuntimeError, match="libosmesa6"):
        CameraHeightmapper(model, CameraConfig())


# ----------------------------------------------------------------------------------------
# Rendering (needs GL)
# ----------------------------------------------------------------------------------------


@pytest.mark.gl
def test_projection_conventions_match_rendering():
    """A straight-down camera over one box: every image pixel whose centre projects
    (through our K and pose) clearly inside the box top reads the box depth, every one
    clearly outside reads the table depth. Checks K, the half-pixel convention and the
    MuJoCo -> OpenCV frame change to 0.05 px."""
    spec = mujoco.MjSpec()
    spec.worldbody.add_geom(type=BOX, size=[0.5, 0.5, 0.05], pos=[0.5, 0.0, -0.05], group=0)
    spec.worldbody.add_geom(
        type=BOX, size=[0.03, 0.05, 0.025], pos=[0.52, 0.01, 0.025], quat=yaw_quat(20.0), group=1
    )
    config = CameraConfig(cameras=(FixedCamera("down", (0.5, 0.0, 0.8)),), width=320, height=240, fovy=40.0)
    add_cameras(spec, config)
    model, data = compile_forward(spec)
    with make_cameras(model, config) as cams:
        image = cams.render(data)[0]

    # Project each pixel centre's viewing ray onto the box-top plane z = 0.05.
    k_inv, pose = np.linalg.inv(image.intrinsics), image.pose
    v, u = np.indices(image.depth.shape)
    rays = pose[:3, :3] @ (k_inv @ np.stack([u.ravel(), v.ravel(), np.ones(u.size)]))
    scale = (0.05 - pose[2, 3]) / rays[2]
    hit = pose[:3, 3:4] + rays * scale
    c, s = math.cos(math.radians(20.0)), math.sin(math.radians(20.0))
    lx = c * (hit[0] - 0.52) + s * (hit[1] - 0.01)
    ly = -s * (hit[0] - 0.52) + c * (hit[1] - 0.01)
    margin = 0.05 * 0.75 / image.intrinsics[1, 1]  # 0.05 px at the box top, in metres
    inside = ((np.abs(lx) < 0.03 - margin) & (np.abs(ly) < 0.05 - margin)).reshape(v.shape)
    outside = ((np.abs(lx) > 0.03 + margin) | (np.abs(ly) > 0.05 + margin)).reshape(v.shape)
    assert inside.sum() > 1000
    np.testing.assert_allclose(image.depth[inside], 0.75, atol=1e-4)
    # Outside the box top: the table (0.8 m) or the box's sides, never the top itself.
    assert np.all(image.depth[outside] > 0.75 + 1e-3)


@pytest.mark.gl
def test_camera_heightmap_agrees_with_raycast(clutter, record_property):
    model, data, _ = clutter
    with RaycastHeightmapper(model) as mapper:
        truth = mapper(data)
    with make_cameras(model, CameraConfig()) as cams:
        seen = cams(data)
    assert seen.depth.shape == (224, 224) and seen.color.shape == (224, 224, 3) and seen.geom_id.shape == (224, 224)
    occupied = truth.depth > 0.005
    assert occupied.sum() > 3000
    # The segmentation render names the geom seen on top as the ray casts do (edges aside).
    inner = cv2.erode(occupied.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    agree = float(np.mean(seen.geom_id[inner] == truth.geom_id[inner]))
    record_property("geom_id_agreement", round(agree, 4))
    assert agree > 0.95, f"camera and ray-cast geom ids agree on {agree:.1%} of inner object pixels"
    error = np.abs(seen.depth - truth.depth)
    mean_mm = float(error[occupied].mean() * 1e3)
    record_property("mean_abs_height_diff_mm", round(mean_mm, 3))  # 0.33 mm when written
    assert mean_mm < 2.0, f"mean |camera - raycast| over occupied pixels = {mean_mm:.3f} mm"
    # The group-2 "robot" at 21-29 cm is invisible: nothing is higher than the clutter.
    assert seen.depth.max() < truth.depth.max() + 0.005
    # Empty table reads 0 away from objects (2 px clear of any occupied pixel).
    near_objects = cv2.dilate(occupied.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert np.abs(seen.depth[~near_objects]).max() < 0.002


@pytest.mark.gl
def test_depth_noise_is_reproducible(clutter):
    model, data, _ = clutter
    noisy = CameraConfig(depth_noise_std=0.002)
    with make_cameras(model, noisy) as cams:
        a = cams.heightmaps(data, rng=np.random.default_rng(7))
        b = cams(data, rng=np.random.default_rng(7))  # __call__ is heightmaps()
        c = cams(data, rng=np.random.default_rng(8))
        with pytest.raises(ValueError, match="Generator"):
            cams(data)
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.color, b.color)
    assert not np.array_equal(a.depth, c.depth)
    with make_cameras(model, CameraConfig()) as clean:
        d = clean(data)
        e = clean(data)
    np.testing.assert_array_equal(d.depth, e.depth)
    assert not np.array_equal(a.depth, d.depth)  # the noise did something


@pytest.mark.gl
def test_close_releases_renderer(clutter):
    model, data, _ = clutter
    cams = make_cameras(model, CameraConfig())
    images = cams.render(data)
    assert [img.name for img in images] == cams.camera_names
    assert images[0].color.shape == (480, 640, 3) and images[0].depth.dtype == np.float32
    cams.close()
    cams.close()
    with pytest.raises(RuntimeError, match="closed"):
        cams.render(data)
