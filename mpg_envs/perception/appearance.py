"""How the camera observation path's scene looks: its lighting, its colours and where its
cameras really are. Each function edits a ``mujoco.MjvScene`` after ``mjv_updateScene``
and before rendering; the model and its data are never touched.

**The colour convention of both observation paths.** An object's colour is its base colour:
the geom's RGBA as :func:`mpg_envs.perception.heightmap.geom_colors` reads it. The ray-cast
heightmaps paint that colour flat. The camera path lights the scene with one directional
light (:class:`Lighting`) whose specular part is 0 and whose ambient and diffuse parts add up
to 1, so a surface facing the light renders exactly at its base colour. By default the light
is all ambient: every surface renders at its base colour, as the ray casts paint it (over the
objects' pixels of the hard track's scenes the two paths then differ by about 1 grey level
on average, against about 60 under the arena's lights, and 5-11 with a 60/40 ambient/diffuse
light from straight above, because the tilted tops of piled objects shade). Shading,
shadows and their variation come with the visual randomization
(:mod:`mpg_envs.perception.visual_randomization`). The arena's own lights and headlight
(tuned for pictures, about twice as bright) are replaced in the camera images only;
``env.render()`` keeps them.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation


@dataclass(frozen=True)
class Lighting:
    """One directional light (the camera path's only light).

    Attributes:
        direction: the direction the light travels in the world (normalised on use);
            ``(0, 0, -1)`` shines straight down.
        ambient: ambient intensity (the share of its base colour every surface shows).
        diffuse: diffuse intensity; a surface facing the light renders at
            ``ambient + diffuse`` times its base colour (1 by default: exactly its base colour).
        shadows: cast shadows (off by default: an all-ambient light casts none, and they
            cost a rendering pass).
    """

    direction: tuple[float, float, float] = (0.0, 0.0, -1.0)
    ambient: float = 1.0
    diffuse: float = 0.0
    shadows: bool = False

    def __post_init__(self) -> None:
        d = np.asarray(self.direction, dtype=float)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-9:
            raise ValueError(f"Lighting.direction must be a non-zero 3-vector, got {self.direction!r}")
        if d[2] >= 0:
            raise ValueError(f"Lighting.direction must point down (z < 0) onto the table, got {self.direction!r}")
        for name in ("ambient", "diffuse"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"Lighting.{name} must be a finite value >= 0, got {value!r}")

    def to_dict(self) -> dict[str, object]:
        d = np.asarray(self.direction, dtype=float)
        return {
            "direction": [round(float(v), 6) for v in d / np.linalg.norm(d)],
            "ambient": round(float(self.ambient), 6),
            "diffuse": round(float(self.diffuse), 6),
            "shadows": bool(self.shadows),
        }


def light_scene(scene: mujoco.MjvScene, lighting: Lighting) -> None:
    """Replace every light of ``scene`` (the model's lights and the headlight) by ``lighting``."""
    direction = np.asarray(lighting.direction, dtype=float)
    direction = direction / np.linalg.norm(direction)
    scene.nlight = 1
    light = scene.lights[0]
    light.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
    light.headlight = 0
    light.dir[:] = direction
    light.pos[:] = -2.0 * direction  # unused by a directional light but for its shadow map
    light.ambient[:] = lighting.ambient
    light.diffuse[:] = lighting.diffuse
    light.specular[:] = 0.0
    light.castshadow = int(lighting.shadows)
    scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = int(lighting.shadows)


def paint_scene(scene: mujoco.MjvScene, geom_rgb: np.ndarray) -> None:
    """Set the RGB of every geom in ``scene`` to ``geom_rgb[geom id]`` (``(ngeom, 3)`` uint8)."""
    rgb = np.asarray(geom_rgb)
    if rgb.ndim != 2 or rgb.shape[1] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"geom_rgb must be a (ngeom, 3) uint8 array, got {rgb.shape} {rgb.dtype}")
    for geom in scene.geoms[: scene.ngeom]:
        if geom.objtype == mujoco.mjtObj.mjOBJ_GEOM and 0 <= geom.objid < rgb.shape[0]:
            geom.rgba[:3] = rgb[geom.objid] / 255.0


def perturbed_pose(
    position: np.ndarray, xmat: np.ndarray, offset: np.ndarray, rotvec: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A camera's world position and 3x3 orientation moved by ``offset`` (m) and turned about
    its own centre by the world-frame rotation vector ``rotvec`` (radians): the pose a camera
    really has when its calibration is off by that much."""
    rot = Rotation.from_rotvec(np.asarray(rotvec, dtype=float)).as_matrix()
    return np.asarray(position, float) + np.asarray(offset, float), rot @ np.asarray(xmat, float).reshape(3, 3)


def place_camera(scene: mujoco.MjvScene, position: np.ndarray, xmat: np.ndarray) -> None:
    """Render ``scene`` from a MuJoCo camera at ``position`` with orientation ``xmat``
    (columns: camera x, y (up), z (backward) in the world), keeping its frustum."""
    xmat = np.asarray(xmat, dtype=float).reshape(3, 3)
    for cam in scene.camera:
        cam.pos[:] = position
        cam.forward[:] = -xmat[:, 2]
        cam.up[:] = xmat[:, 1]
