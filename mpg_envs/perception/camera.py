"""Optional camera observation mode: fixed RGB-D cameras rendered by MuJoCo, back-projected
into heightmaps like a real RealSense pipeline (needs OpenGL).

Usage::

    spec = ...                                 # the env's scene, before compiling
    add_cameras(spec, config)                  # fixed cameras in the worldbody
    model = spec.compile(); data = mujoco.MjData(model)
    with CameraHeightmapper(model, config) as cams:
        maps = cams.heightmaps(data, rng=np.random.default_rng(0))

Rendering needs an OpenGL context. On a headless Linux machine set ``MUJOCO_GL=egl`` (or
``osmesa``) *before the first* ``import mujoco`` in the process (MuJoCo picks its GL
backend at import time) and install the Debian packages ``libegl1 libegl-mesa0
libgl1-mesa-dri`` (EGL) or ``libosmesa6`` (OSMesa). The default ray-cast observations
(:class:`mpg_envs.perception.heightmap.RaycastHeightmapper`) need none of this.

Only geom groups 0 (table) and 1 (objects) are drawn, so the robot never appears in the
images, just as it is invisible to the ray-cast heightmaps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from mpg_envs.grid.workspace import Workspace
from mpg_envs.perception.appearance import Lighting, light_scene, paint_scene, perturbed_pose, place_camera
from mpg_envs.perception.depth_noise import corrupt_depth
from mpg_envs.perception.frames import SceneFrames
from mpg_envs.perception.heightmap import VISIBLE_GEOM_GROUPS, Heightmaps, geomgroup_mask
from mpg_envs.perception.rgbd import fuse_heightmaps, heightmap_from_rgbd
from mpg_envs.perception.visual_randomization import EpisodeVisuals, randomized_geom_colors

# OpenCV camera axes (x right, y down, z forward) expressed in MuJoCo's camera frame
# (x right, y up, looking along -z): flip y and z.
_MJ_TO_CV = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class FixedCamera:
    """A camera fixed in the world, looking from ``position`` at ``target`` (metres).

    The image has no roll (its x axis is horizontal); a camera looking exactly straight down
    has the image top toward world +x.
    """

    name: str
    position: tuple[float, float, float]
    target: tuple[float, float, float] = (0.5, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("camera name must be non-empty")
        if len(self.position) != 3 or len(self.target) != 3:
            raise ValueError(f"camera {self.name!r}: position and target must be 3-vectors")
        if np.linalg.norm(np.subtract(self.target, self.position)) < 1e-6:
            raise ValueError(f"camera {self.name!r}: target must differ from position")


def _default_cameras() -> tuple[FixedCamera, ...]:
    # Two fixed cameras as in the paper's simulation: one nearly overhead, one oblique from
    # the far side of the table (the robot stands at the origin, behind the workspace).
    return (
        FixedCamera("mpg_cam_overhead", position=(0.56, 0.0, 0.85)),
        FixedCamera("mpg_cam_front", position=(1.15, 0.0, 0.62)),
    )


@dataclass(frozen=True)
class CameraConfig:
    """Fixed RGB-D cameras of the camera observation mode.

    Attributes:
        cameras: the cameras (names must be unique in the model).
        width, height: image size in pixels.
        fovy: vertical field of view, degrees (square pixels, centred principal point).
            The default 35 makes the workspace fill most of the default cameras' frames:
            about 1.1 mm per image pixel on the table from the overhead camera, finer than
            the 2 mm heightmap pixels (at 45, surfaces sloping away from the camera were
            sampled more coarsely than the heightmap and showed dotted gaps).
        depth_noise_std: standard deviation (m) of zero-mean Gaussian noise added to every
            valid depth reading (0 = noise-free); the noise comes from the
            ``numpy.random.Generator`` passed to :meth:`CameraHeightmapper.heightmaps`.
        near, far: valid depth range (m) of the sensor; readings outside it are invalid.
        background_color: RGB of heightmap pixels that no camera sees.
        lighting: the one light of the colour images (:class:`~mpg_envs.perception.appearance.Lighting`;
            the default renders every upward-facing surface at its base colour, the
            ray-cast heightmaps' colour). The model's own lights are not used.
    """

    cameras: tuple[FixedCamera, ...] = field(default_factory=_default_cameras)
    width: int = 640
    height: int = 480
    fovy: float = 35.0
    depth_noise_std: float = 0.0
    near: float = 0.1
    far: float = 3.0
    background_color: tuple[int, int, int] = (0, 0, 0)
    lighting: Lighting = field(default_factory=Lighting)

    def __post_init__(self) -> None:
        if not self.cameras:
            raise ValueError("CameraConfig needs at least one camera")
        names = [cam.name for cam in self.cameras]
        if len(set(names)) != len(names):
            raise ValueError(f"camera names must be unique, got {names}")
        if self.width < 1 or self.height < 1:
            raise ValueError(f"image size must be positive, got {self.width} x {self.height}")
        if not 0.0 < self.fovy < 180.0:
            raise ValueError(f"fovy must be in (0, 180) degrees, got {self.fovy}")
        if self.depth_noise_std < 0:
            raise ValueError(f"depth_noise_std must be >= 0, got {self.depth_noise_std}")
        if not 0.0 < self.near < self.far:
            raise ValueError(f"need 0 < near < far, got near={self.near}, far={self.far}")


@dataclass
class CameraImage:
    """One rendered RGB-D frame in OpenCV conventions.

    Attributes:
        name: camera name.
        color: ``(H, W, 3)`` uint8 RGB.
        depth: ``(H, W)`` float32 metres along the optical axis; 0 where invalid.
        intrinsics: 3x3 pinhole matrix ``K``.
        pose: 4x4 camera-to-world transform of the OpenCV camera frame.
        geom_id: ``(H, W)`` int32 id of the geom seen at each pixel (MuJoCo's segmentation
            render), -1 where no geom is seen.
    """

    name: str
    color: np.ndarray
    depth: np.ndarray
    intrinsics: np.ndarray
    pose: np.ndarray
    geom_id: np.ndarray | None = None


# ----------------------------------------------------------------------------------------
# Pure geometry helpers
# ----------------------------------------------------------------------------------------


def look_at_xmat(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """3x3 rotation (columns = camera axes in world) of a MuJoCo camera at ``position``
    looking at ``target``: -z toward the target, x horizontal (right), y up in the image.
    Looking straight down, the image's up direction (+y) is world +x."""
    forward = np.asarray(target, float) - np.asarray(position, float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-6:  # looking straight up or down: pick image-up = +x
        right = np.cross(forward, [1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return np.stack([right, up, -forward], axis=1)


def camera_intrinsics(fovy: float, width: int, height: int) -> np.ndarray:
    """OpenCV 3x3 ``K`` of a MuJoCo perspective camera with vertical field of view
    ``fovy`` degrees rendered at ``width`` x ``height`` (square pixels, principal point at
    the image centre; OpenCV puts pixel centres at integer coordinates, hence ``- 0.5``)."""
    if not 0.0 < fovy < 180.0 or width < 1 or height < 1:
        raise ValueError(f"need 0 < fovy < 180 and a positive image size, got {fovy}, {width} x {height}")
    focal = 0.5 * height / math.tan(math.radians(fovy) / 2.0)
    return np.array([[focal, 0.0, width / 2.0 - 0.5], [0.0, focal, height / 2.0 - 0.5], [0.0, 0.0, 1.0]])


def opencv_camera_pose(xpos: np.ndarray, xmat: np.ndarray) -> np.ndarray:
    """4x4 camera-to-world transform in OpenCV convention from a MuJoCo camera's world
    position and orientation (``data.cam_xpos[i]``, ``data.cam_xmat[i]``)."""
    pose = np.eye(4)
    pose[:3, :3] = np.asarray(xmat, float).reshape(3, 3) @ _MJ_TO_CV
    pose[:3, 3] = np.asarray(xpos, float)
    return pose


def add_cameras(spec: mujoco.MjSpec, config: CameraConfig | None = None) -> list[str]:
    """Add the configured fixed cameras to the worldbody of ``spec``; returns their names.

    Also enlarges the model's offscreen framebuffer if the images are larger than it.

    Raises:
        ValueError: if a camera of the same name already exists in ``spec``.
    """
    config = config if config is not None else CameraConfig()
    names = []
    for cam in config.cameras:
        if spec.camera(cam.name) is not None:
            raise ValueError(f"spec already has a camera named {cam.name!r}")
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, look_at_xmat(np.array(cam.position), np.array(cam.target)).ravel())
        spec.worldbody.add_camera(
            name=cam.name,
            pos=list(cam.position),
            quat=quat.tolist(),
            fovy=float(config.fovy),
            resolution=[config.width, config.height],
        )
        names.append(cam.name)
    glob = spec.visual.global_
    glob.offwidth = max(int(glob.offwidth), config.width)
    glob.offheight = max(int(glob.offheight), config.height)
    return names


# ----------------------------------------------------------------------------------------
# Rendering
# ----------------------------------------------------------------------------------------


class CameraHeightmapper:
    """Render the configured cameras and fuse their back-projected heightmaps.

    Each camera is rendered in colour under the configured light (or an episode's), and in
    depth with segmentation from one more pass (:class:`~mpg_envs.perception.frames.SceneFrames`;
    only geom groups 0 and 1 visible), converted to the OpenCV camera convention, optionally
    corrupted by depth noise, back-projected with :func:`heightmap_from_rgbd`, and all views
    are fused per pixel (:func:`fuse_heightmaps`). Holds an OpenGL context: call
    :meth:`close` or use it as a context manager.

    Raises:
        ValueError: if a configured camera is missing from ``model`` (call
            :func:`add_cameras` on the spec before compiling) or is not a plain perspective
            camera with ``fovy``.
        RenderUnavailableError: (a ``RuntimeError``) if no OpenGL context can be created in
            this process (the message says how to fix it).
    """

    def __init__(self, model: mujoco.MjModel, config: CameraConfig | None = None, workspace: Workspace | None = None) -> None:
        self.model = model
        self.config = config if config is not None else CameraConfig()
        self.workspace = workspace if workspace is not None else Workspace()
        self._renderer: SceneFrames | None = None
        self._camera_ids: list[int] = []
        self._intrinsics: list[np.ndarray] = []
        for cam in self.config.cameras:
            cam_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, cam.name)
            if cam_id < 0:
                raise ValueError(f"model has no camera {cam.name!r}: call add_cameras(spec, config) before compiling")
            if int(model.cam_projection[cam_id]) != int(mujoco.mjtProjection.mjPROJ_PERSPECTIVE) or np.any(
                model.cam_sensorsize[cam_id] > 0
            ):
                raise ValueError(f"camera {cam.name!r} must be a perspective camera defined by fovy")
            self._camera_ids.append(cam_id)
            self._intrinsics.append(camera_intrinsics(float(model.cam_fovy[cam_id]), self.config.width, self.config.height))

        self._option = mujoco.MjvOption()
        self._option.geomgroup[:] = geomgroup_mask(VISIBLE_GEOM_GROUPS)
        # Nothing but table and object geoms: no sites, tendons, flexes or skins either.
        for groups in (
            self._option.sitegroup,
            self._option.tendongroup,
            self._option.flexgroup,
            self._option.skingroup,
        ):
            groups[:] = 0

        # One record of GL failure per process, shared with env.render(): a retry can abort.
        self._renderer = SceneFrames(
            model,
            self.config.height,
            self.config.width,
            purpose="Camera observations (the default ray-cast observations need none)",
        )
        # Mirror images of the objects in a reflective table would paint wrong colours.
        self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        self._colors: tuple[EpisodeVisuals | None, np.ndarray] | None = None  # (visuals, geom colours)

    @property
    def camera_names(self) -> list[str]:
        """Names of the cameras, in configuration order."""
        return [cam.name for cam in self.config.cameras]

    def render(
        self, data: mujoco.MjData, rng: np.random.Generator | None = None, visuals: EpisodeVisuals | None = None
    ) -> list[CameraImage]:
        """Render every camera (``data`` after ``mj_forward`` or a step).

        Depth noise (``config.depth_noise_std > 0``) is drawn from ``rng``, camera by
        camera in configuration order, so a seeded generator reproduces it exactly.
        ``visuals`` (one episode's :class:`~mpg_envs.perception.visual_randomization.EpisodeVisuals`)
        replaces the light, recolours table and objects, renders each camera from its true
        pose (calibrated pose moved by the drawn error; ``pose`` stays the calibrated one,
        as a real pipeline only knows that) and corrupts the depth as a RealSense does
        (drawn from ``rng`` too).

        Raises:
            ValueError: if noise is configured but no ``rng`` is given, or ``visuals`` has
                calibration errors of fewer cameras than this mode has.
            RuntimeError: after :meth:`close`.
        """
        if self._renderer is None:
            raise RuntimeError("CameraHeightmapper is closed")
        std = self.config.depth_noise_std
        noisy = std > 0 or (visuals is not None and visuals.depth_noise is not None)
        if noisy and rng is None:
            raise ValueError("depth noise needs a numpy.random.Generator: pass rng=np.random.default_rng(seed)")
        if visuals is not None and len(visuals.camera_offsets) < len(self._camera_ids):
            raise ValueError(
                f"visuals hold calibration errors of {len(visuals.camera_offsets)} "
                f"cameras, this mode has {len(self._camera_ids)}"
            )
        lighting = self.config.lighting if visuals is None else visuals.lighting
        colors = self._geom_colors(visuals)
        images = []
        for k, (cam_id, name, intrinsics) in enumerate(
            zip(self._camera_ids, self.camera_names, self._intrinsics, strict=True)
        ):
            self._renderer.update(data, cam_id, self._option)
            scene = self._renderer.scene
            light_scene(scene, lighting)
            if visuals is not None:
                paint_scene(scene, colors)
                place_camera(
                    scene,
                    *perturbed_pose(
                        data.cam_xpos[cam_id], data.cam_xmat[cam_id], visuals.camera_offsets[k], visuals.camera_rotations[k]
                    ),
                )
            color = self._renderer.color()
            depth, geom_id = self._renderer.depth_and_segmentation()
            depth = depth.astype(np.float64)
            if std > 0:
                depth += rng.normal(0.0, std, size=depth.shape)  # type: ignore[union-attr]
            valid = (depth >= self.config.near) & (depth <= self.config.far)
            depth = np.where(valid, depth, 0.0)
            if visuals is not None and visuals.depth_noise is not None:
                depth = corrupt_depth(depth, color, visuals.depth_noise, rng)  # type: ignore[arg-type]
            pose = opencv_camera_pose(data.cam_xpos[cam_id], data.cam_xmat[cam_id])
            images.append(
                CameraImage(
                    name=name,
                    color=color,
                    depth=depth.astype(np.float32),
                    intrinsics=intrinsics.copy(),
                    pose=pose,
                    geom_id=geom_id,
                )
            )
        return images

    def _geom_colors(self, visuals: EpisodeVisuals | None) -> np.ndarray:
        """The episode's geom colours, computed once per episode's visuals."""
        if self._colors is None or self._colors[0] is not visuals:
            self._colors = (visuals, randomized_geom_colors(self.model, visuals))
        return self._colors[1]

    def heightmaps(
        self, data: mujoco.MjData, rng: np.random.Generator | None = None, visuals: EpisodeVisuals | None = None
    ) -> Heightmaps:
        """Fused colour/depth heightmaps of all cameras, with the geom seen at each pixel from
        the segmentation render (``geom_id``); ``rng`` and ``visuals`` as in :meth:`render`."""
        maps = [
            heightmap_from_rgbd(
                img.color, img.depth, img.intrinsics, img.pose, self.workspace, self.config.background_color, img.geom_id
            )
            for img in self.render(data, rng, visuals)
        ]
        return fuse_heightmaps(maps)

    def __call__(
        self, data: mujoco.MjData, rng: np.random.Generator | None = None, visuals: EpisodeVisuals | None = None
    ) -> Heightmaps:
        """Same as :meth:`heightmaps`."""
        return self.heightmaps(data, rng, visuals)

    def close(self) -> None:
        """Release the renderer and its OpenGL context (idempotent)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self) -> CameraHeightmapper:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        # Best effort if the user forgot close(); the GL context may already be gone.
        try:
            self.close()
        except Exception:
            pass
