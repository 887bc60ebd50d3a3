"""Seeded visual randomization: what an episode's observations look like when the world is
not the simulator's clean one (the env option ``visual_randomization``).

:class:`VisualRandomization` gives the ranges; :func:`draw_visuals` draws one episode's
values (:class:`EpisodeVisuals`) from an integer seed, so the same seed gives the same
light, colours, camera errors and depth noise. What applies where:

- light direction, strength and shadows: the camera path only (the ray casts paint flat colours);
- object and table colours: both paths (:func:`randomized_geom_colors`);
- camera pose (a calibration error: the image comes from the true pose, the back-projection
  uses the calibrated one): the camera path, and with ``raycast_misregistration`` the ray-cast
  path as the same cameras would place it (:mod:`mpg_envs.perception.misregistration`);
- depth noise and missing depth: both, each camera image on the camera path, and on the
  ray-cast path as a camera :data:`OVERHEAD_CAMERA_Z` straight above would see the heightmap
  (:func:`randomized_raycast`).

The maths are pure functions: :func:`jitter_colors` here, the pose error in
:func:`mpg_envs.perception.appearance.perturbed_pose`, the sensor in
:mod:`mpg_envs.perception.depth_noise`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import mujoco
import numpy as np

from mpg_envs.perception.appearance import Lighting
from mpg_envs.perception.depth_noise import DepthNoise, corrupt_heights
from mpg_envs.perception.heightmap import Heightmaps, RaycastHeightmapper, geom_colors
from mpg_envs.perception.misregistration import misregistered_heightmaps
from mpg_envs.settings_fields import check_known_fields

OVERHEAD_CAMERA_Z = 0.85
"""World height (m) of the virtual camera whose depth noise the ray-cast path takes: the
camera mode's overhead camera."""

CAMERA_SLOTS = 4
"""Camera calibration errors drawn per episode (the k-th camera of the camera mode takes row k)."""

MAX_OBJECT_SLOTS = 64
"""Object colours drawn per episode (object bodies take them in body order): more than any scene holds."""

_STREAM = 0x56495355  # spawn key of the visual stream: independent of the scene's draws


def _check_range(name: str, value: Any, low: float, high: float) -> None:
    if not (isinstance(value, (tuple, list)) and len(value) == 2 and low <= value[0] <= value[1] <= high):
        raise ValueError(
            f"VisualRandomization.{name} must be a (low, high) pair with {low} <= low <= high <= {high}, got {value!r}"
        )


@dataclass(frozen=True)
class VisualRandomization:
    """Ranges of the visual randomization (each value is drawn uniformly in its range).

    Attributes:
        light_tilt: largest angle (degrees) of the light from straight down (azimuth uniform).
        light_intensity: range of ``ambient + diffuse`` (1: a surface facing the light shows
            its base colour).
        ambient_share: range of ``ambient / (ambient + diffuse)``.
        shadows: the light casts shadows.
        object_brightness: each object's colour is scaled by a factor in ``1 +- this``.
        object_hue: ... and each of its channels by a further factor in ``1 +- this``.
        table_brightness, table_hue: the same for the table.
        camera_position_error: largest distance (m) between a camera's true and calibrated
            position (direction uniform, distance uniform up to this).
        camera_rotation_error: largest angle (degrees) between its true and calibrated
            orientation (axis uniform).
        depth_noise: the depth sensor's noise and holes (``None``: clean depth).
        depth_noise_scale: range of a factor on ``depth_noise``'s standard deviations.
        raycast_misregistration: the ray-cast path also places its heightmaps as the camera
            mode's cameras with this episode's calibration errors would (each camera's view
            moved by its own error, fused by the highest reading), so a policy trained on ray
            casts meets the camera track's misplacement of image against target mask. Off by
            default: the ray-cast path then stays registered.
    """

    light_tilt: float = 30.0
    light_intensity: tuple[float, float] = (0.85, 1.15)
    ambient_share: tuple[float, float] = (0.4, 0.8)
    shadows: bool = True
    object_brightness: float = 0.15
    object_hue: float = 0.1
    table_brightness: float = 0.15
    table_hue: float = 0.05
    camera_position_error: float = 0.01
    camera_rotation_error: float = 1.0
    depth_noise: DepthNoise | None = field(default_factory=DepthNoise)
    depth_noise_scale: tuple[float, float] = (0.5, 1.5)
    raycast_misregistration: bool = False

    def __post_init__(self) -> None:
        if not 0.0 <= self.light_tilt < 90.0:
            raise ValueError(f"VisualRandomization.light_tilt must be in [0, 90) degrees, got {self.light_tilt!r}")
        _check_range("light_intensity", self.light_intensity, 0.0, 10.0)
        _check_range("ambient_share", self.ambient_share, 0.0, 1.0)
        _check_range("depth_noise_scale", self.depth_noise_scale, 0.0, 100.0)
        for name in ("object_brightness", "object_hue", "table_brightness", "table_hue"):
            if not 0.0 <= getattr(self, name) < 1.0:
                raise ValueError(f"VisualRandomization.{name} must be in [0, 1), got {getattr(self, name)!r}")
        if not 0.0 <= self.camera_position_error <= 0.1:
            raise ValueError(
                f"VisualRandomization.camera_position_error must be in [0, 0.1] m, got {self.camera_position_error!r}"
            )
        if not 0.0 <= self.camera_rotation_error <= 10.0:
            raise ValueError(
                f"VisualRandomization.camera_rotation_error must be in [0, 10] degrees, got {self.camera_rotation_error!r}"
            )
        if not isinstance(self.raycast_misregistration, bool):
            raise ValueError(
                f"VisualRandomization.raycast_misregistration must be True or False, got {self.raycast_misregistration!r}"
            )
        if self.depth_noise is not None and not isinstance(self.depth_noise, DepthNoise):
            raise ValueError(f"VisualRandomization.depth_noise must be a DepthNoise or None, got {self.depth_noise!r}")

    @classmethod
    def from_option(cls, value: Any) -> VisualRandomization | None:
        """The env option's value -> ranges: ``None``/``False`` (off), ``True`` (the
        defaults), a mapping of fields to change (``depth_noise`` itself a mapping or
        ``None``), or a :class:`VisualRandomization`."""
        if value is None or value is False:
            return None
        if value is True:
            return cls()
        if isinstance(value, cls):
            return value
        if isinstance(value, Mapping):
            check_known_fields(cls, value, "visual_randomization")
            data = dict(value)
            if isinstance(data.get("depth_noise"), Mapping):
                data["depth_noise"] = DepthNoise(**data["depth_noise"])
            for key in ("light_intensity", "ambient_share", "depth_noise_scale"):
                if isinstance(data.get(key), list):
                    data[key] = tuple(data[key])
            return cls(**data)
        raise ValueError(
            "visual_randomization must be None, False, True, a dict of "
            f"VisualRandomization fields or a VisualRandomization, got {value!r}"
        )

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["depth_noise"] = None if self.depth_noise is None else self.depth_noise.to_dict()
        return data


@dataclass(frozen=True, eq=False)  # arrays inside: compare to_dict() values
class EpisodeVisuals:
    """One episode's drawn values (:func:`draw_visuals`).

    Attributes:
        seed: the integer they were drawn from (also seeds each observation's depth noise).
        lighting: the light.
        table_gain: ``(3,)`` factors on the table's RGB.
        object_gains: ``(MAX_OBJECT_SLOTS, 3)`` factors on each object's RGB (the k-th object
            body in body order takes row k).
        camera_offsets: ``(CAMERA_SLOTS, 3)`` true minus calibrated camera position, metres.
        camera_rotations: ``(CAMERA_SLOTS, 3)`` rotation vectors (radians, world frame) from the
            calibrated to the true camera orientation.
        depth_noise: this episode's depth noise (``None``: clean).
        raycast_misregistration: the ray-cast path places its heightmaps with the camera
            errors (:attr:`VisualRandomization.raycast_misregistration`).
    """

    seed: int
    lighting: Lighting
    table_gain: np.ndarray
    object_gains: np.ndarray
    camera_offsets: np.ndarray
    camera_rotations: np.ndarray
    depth_noise: DepthNoise | None
    raycast_misregistration: bool = False

    def noise_rng(self, observation: int) -> np.random.Generator:
        """The generator of observation ``observation``'s depth noise (same seed and index,
        same noise: a step tried and undone sees the noise the step then sees)."""
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(_STREAM, 1, int(observation))))

    def to_dict(self, num_objects: int | None = None) -> dict[str, Any]:
        """JSON-ready values, rounded; object gains of the first ``num_objects`` objects."""
        n = MAX_OBJECT_SLOTS if num_objects is None else int(num_objects)
        r = lambda a: np.round(np.asarray(a, float), 5).tolist()  # noqa: E731
        extra = (
            {"raycast_misregistration": True} if self.raycast_misregistration else {}
        )  # records without it stay as they were
        return {
            "seed": int(self.seed),
            "lighting": self.lighting.to_dict(),
            "table_gain": r(self.table_gain),
            "object_gains": r(self.object_gains[:n]),
            "camera_offsets_m": r(self.camera_offsets),
            "camera_rotations_deg": r(np.degrees(np.linalg.norm(self.camera_rotations, axis=1))),
            "depth_noise": None if self.depth_noise is None else self.depth_noise.to_dict(),
            **extra,
        }


def _in_ball(rng: np.random.Generator, count: int, radius: float) -> np.ndarray:
    """``count`` vectors of uniform direction and a length uniform in ``[0, radius]``."""
    direction = rng.standard_normal((count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return direction * rng.uniform(0.0, radius, size=(count, 1))


def _gains(rng: np.random.Generator, count: int, brightness: float, hue: float) -> np.ndarray:
    return rng.uniform(1 - brightness, 1 + brightness, size=(count, 1)) * rng.uniform(1 - hue, 1 + hue, size=(count, 3))


def draw_visuals(config: VisualRandomization, seed: int) -> EpisodeVisuals:
    """One episode's visuals, drawn from ``seed`` alone (a stream of its own, so the scene's
    draws are unchanged)."""
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(_STREAM, 0)))
    tilt = np.radians(rng.uniform(0.0, config.light_tilt))
    azimuth = rng.uniform(0.0, 2 * np.pi)
    direction = (np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), -np.cos(tilt))
    intensity = rng.uniform(*config.light_intensity)
    share = rng.uniform(*config.ambient_share)
    dx, dy, dz = (float(v) for v in direction)
    lighting = Lighting((dx, dy, dz), intensity * share, intensity * (1 - share), config.shadows)
    table_gain = _gains(rng, 1, config.table_brightness, config.table_hue)[0]
    object_gains = _gains(rng, MAX_OBJECT_SLOTS, config.object_brightness, config.object_hue)
    offsets = _in_ball(rng, CAMERA_SLOTS, config.camera_position_error)
    rotations = _in_ball(rng, CAMERA_SLOTS, np.radians(config.camera_rotation_error))
    noise = None
    if config.depth_noise is not None:
        scale = rng.uniform(*config.depth_noise_scale)
        base = config.depth_noise
        noise = DepthNoise(**{**base.to_dict(), "base_std": base.base_std * scale, "quadratic": base.quadratic * scale})
    return EpisodeVisuals(
        int(seed), lighting, table_gain, object_gains, offsets, rotations, noise, bool(config.raycast_misregistration)
    )


def episode_visuals(config: VisualRandomization | None, seed: int | None, rng: np.random.Generator) -> EpisodeVisuals | None:
    """An env reset's visuals: ``None`` when randomization is off; else drawn from the reset's
    ``seed``, or from a seed drawn from ``rng`` (the env's generator) when the reset has none."""
    if config is None:
        return None
    return draw_visuals(config, int(rng.integers(2**63)) if seed is None else int(seed))


def jitter_colors(rgb: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """uint8 RGB colours times per-channel ``gains`` (broadcast), rounded and kept in 0..255."""
    rgb = np.asarray(rgb)
    if rgb.dtype != np.uint8 or rgb.shape[-1:] != (3,):
        raise ValueError(f"rgb must be a (..., 3) uint8 array, got {rgb.shape} {rgb.dtype}")
    return np.clip(np.round(rgb.astype(np.float64) * np.asarray(gains, dtype=np.float64)), 0, 255).astype(np.uint8)


def object_bodies(model: mujoco.MjModel, object_group: int = 1) -> np.ndarray:
    """Ids of the bodies that carry an object geom (``object_group``), ascending."""
    return np.unique(model.geom_bodyid[model.geom_group == object_group])


def randomized_geom_colors(model: mujoco.MjModel, visuals: EpisodeVisuals | None) -> np.ndarray:
    """``(ngeom, 3)`` uint8 colour of every geom this episode: the base colours
    (:func:`geom_colors`), the table's (group 0) times ``table_gain`` and each object's
    (group 1; all geoms of one body alike) times its body's row of ``object_gains``."""
    base = geom_colors(model)
    if visuals is None:
        return base
    gains = np.ones((model.ngeom, 3))
    gains[model.geom_group == 0] = visuals.table_gain
    bodies = object_bodies(model)
    if bodies.size > MAX_OBJECT_SLOTS:
        raise ValueError(f"the model has {bodies.size} object bodies; visual randomization colours at most {MAX_OBJECT_SLOTS}")
    slot = np.full(model.nbody, -1)
    slot[bodies] = np.arange(bodies.size)
    objects = model.geom_group == 1
    gains[objects] = visuals.object_gains[slot[model.geom_bodyid[objects]]]
    return jitter_colors(base, gains)


def randomized_raycast(
    raycaster: RaycastHeightmapper,
    data: mujoco.MjData,
    visuals: EpisodeVisuals,
    rng: np.random.Generator,
    background_color: tuple[int, int, int] = (0, 0, 0),
    camera_centres: np.ndarray | None = None,
) -> Heightmaps:
    """The ray-cast heightmaps with an episode's colours, placed as cameras at
    ``camera_centres`` with its calibration errors would place them when it asks for that
    (``raycast_misregistration``; camera k takes row k of the errors), and, when it has one,
    its depth noise as a camera at :data:`OVERHEAD_CAMERA_Z` straight above would give it:
    pixels that lose their depth read height 0, ``background_color`` and geom -1, as the
    camera path's pixels that no camera sees. The light does not apply.

    Raises:
        ValueError: misregistration asked for without ``camera_centres``, or more cameras
            than :data:`CAMERA_SLOTS`.
    """
    maps = raycaster.heightmaps(data, randomized_geom_colors(raycaster.model, visuals))
    ws = raycaster.workspace
    if visuals.raycast_misregistration:
        if camera_centres is None or not 1 <= len(camera_centres) <= CAMERA_SLOTS:
            raise ValueError(
                f"raycast_misregistration needs the calibrated centres of 1 to {CAMERA_SLOTS} cameras, got {camera_centres!r}"
            )
        k = len(camera_centres)
        maps = misregistered_heightmaps(
            maps, ws, camera_centres, visuals.camera_offsets[:k], visuals.camera_rotations[:k], background_color
        )
    if visuals.depth_noise is None:
        return maps
    depth, lost = corrupt_heights(
        maps.depth, maps.color, visuals.depth_noise, rng, OVERHEAD_CAMERA_Z - ws.z_min, ws.z_max - ws.z_min
    )
    color = maps.color.copy()
    color[lost] = np.asarray(background_color, dtype=np.uint8)
    geom_id = None if maps.geom_id is None else np.where(lost, -1, maps.geom_id).astype(np.int32)
    return Heightmaps(color=color, depth=depth, geom_id=geom_id)
