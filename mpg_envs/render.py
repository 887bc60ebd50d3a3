"""Pictures of the scene for people (``render_mode="rgb_array"``): needs OpenGL.

Headless machines render through EGL or OSMesa: set ``MUJOCO_GL=egl`` (or ``osmesa``)
before Python imports mujoco, with Debian's ``libegl1 libegl-mesa0 libgl1-mesa-dri``
(or ``libosmesa6``) installed. Observations never need this.
"""

from __future__ import annotations

import mujoco
import numpy as np

GL_HELP = (
    "MuJoCo could not create an OpenGL context. On a headless machine set MUJOCO_GL=egl "
    "(or osmesa) before importing mujoco, with the Debian packages libegl1 libegl-mesa0 "
    "libgl1-mesa-dri (or libosmesa6) installed"
)


def make_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """A ``mujoco.Renderer``, or a ``RuntimeError`` explaining how to get OpenGL."""
    try:
        return mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:  # mujoco raises several types depending on the backend
        raise RuntimeError(f"{GL_HELP} ({type(exc).__name__}: {exc})") from exc


class OverviewRenderer:
    """Renders the arena's ``overview`` camera (robot, table and objects) to RGB."""

    def __init__(self, model: mujoco.MjModel, height: int = 480, width: int = 640, camera: str = "overview"):
        self.model = model
        self.camera = camera
        self._renderer = make_renderer(model, height, width)

    def render(self, data: mujoco.MjData) -> np.ndarray:
        """An ``(H, W, 3)`` uint8 picture of the current state."""
        self._renderer.update_scene(data, camera=self.camera)
        return self._renderer.render().copy()

    def close(self) -> None:
        self._renderer.close()


def render_overview(model: mujoco.MjModel, height: int = 480, width: int = 640) -> OverviewRenderer:
    return OverviewRenderer(model, height, width)
