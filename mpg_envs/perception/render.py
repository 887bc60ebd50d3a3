"""Pictures of the scene for people (``render_mode="rgb_array"``); they need OpenGL.

Observations never need OpenGL (heightmaps are ray cast). Headless Linux machines render
through EGL or OSMesa: :func:`choose_gl_backend` (run when :mod:`mpg_envs` is imported,
before mujoco) sets ``MUJOCO_GL=egl`` when ``MUJOCO_GL`` is unset, there is no display and
libEGL loads, else ``osmesa`` when libOSMesa loads. An explicit ``MUJOCO_GL`` is respected:
set it (``egl``, ``osmesa`` or ``glfw``) before the first ``import mpg_envs`` or ``import
mujoco`` to choose the backend yourself. Nothing is set when mujoco was imported first, off
Linux, or when a display is present (``DISPLAY`` / ``WAYLAND_DISPLAY``).

Without a working backend, rendering raises :class:`RenderUnavailableError` and the process
carries on: the first failure is remembered and later attempts raise it again without
touching OpenGL, because a second context attempt after a failed one can abort the whole
interpreter (seen with GLFW and no display: ``libc++abi: __cxa_guard_acquire detected
recursive initialization``).
"""

from __future__ import annotations

import ctypes
import os
import sys
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, TypeVar

import numpy as np

if TYPE_CHECKING:
    import mujoco

T = TypeVar("T")

GL_PACKAGES = "libegl1 libegl-mesa0 libgl1-mesa-dri (EGL) or libosmesa6 (OSMesa)"
GL_HELP = (
    "On a headless machine set MUJOCO_GL=egl (or osmesa) before mujoco is imported, with the "
    f"Debian packages {GL_PACKAGES} installed"
)

# Shared-library names tried for each headless backend, in order.
GL_LIBRARIES: dict[str, tuple[str, ...]] = {
    "egl": ("libEGL.so.1", "libEGL.so"),
    "osmesa": ("libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so"),
}


class RenderUnavailableError(RuntimeError):
    """No OpenGL context can be created in this process, so nothing can be rendered.

    The message names the ``MUJOCO_GL`` backend that failed and the packages to install.
    Observations, ``reset`` and ``step`` are unaffected.
    """


def default_gl_backend(environ: Mapping[str, str], platform: str, library_loads: Callable[[str], bool]) -> str | None:
    """The ``MUJOCO_GL`` value to set, or ``None`` to leave MuJoCo's choice alone.

    ``None`` when the user set ``MUJOCO_GL``, off Linux (MuJoCo's defaults work there) and on
    Linux with a display (GLFW works); otherwise the first of ``egl``, ``osmesa`` whose
    library loads (``library_loads(backend)``), or ``None`` when neither does.
    """
    if "MUJOCO_GL" in environ or not platform.startswith("linux"):
        return None
    if environ.get("DISPLAY") or environ.get("WAYLAND_DISPLAY"):
        return None
    for backend in ("egl", "osmesa"):
        if library_loads(backend):
            return backend
    return None


def gl_library_loads(backend: str) -> bool:
    """Whether one of ``backend``'s shared libraries (:data:`GL_LIBRARIES`) can be loaded."""
    for name in GL_LIBRARIES[backend]:
        try:
            ctypes.CDLL(name)
            return True
        except OSError:
            continue
    return False


def choose_gl_backend() -> str | None:
    """Set ``MUJOCO_GL`` per :func:`default_gl_backend` unless mujoco is already imported.

    Returns the backend in effect (``MUJOCO_GL``), ``None`` for MuJoCo's own default.
    """
    if "mujoco" not in sys.modules:  # MuJoCo reads MUJOCO_GL once, at import
        backend = default_gl_backend(os.environ, sys.platform, gl_library_loads)
        if backend is not None:
            os.environ["MUJOCO_GL"] = backend
    return os.environ.get("MUJOCO_GL")


# The first failure to create a GL context in this process (see the module docstring).
_gl_failure: str | None = None


def open_gl(create: Callable[[], T], purpose: str = "Rendering") -> T:
    """``create()`` (something that makes an OpenGL context), or :class:`RenderUnavailableError`
    explaining how to get OpenGL. After one failure in this process, later calls raise the
    same error without calling ``create`` (see the module docstring).

    ``ValueError`` (an image larger than the model's offscreen framebuffer) passes through:
    MuJoCo's message says what to change. ``purpose`` starts the error message.
    """
    global _gl_failure
    if _gl_failure is None:
        try:
            return create()
        except ValueError:
            raise
        except Exception as exc:  # the GL backends raise various types
            backend = os.environ.get("MUJOCO_GL", "<unset>")
            _gl_failure = f"could not create an OpenGL context (MUJOCO_GL={backend}: {type(exc).__name__}: {exc})"
    raise RenderUnavailableError(f"{purpose} needs OpenGL, which is unavailable in this process: {_gl_failure}. {GL_HELP}")


def make_renderer(model: mujoco.MjModel, height: int, width: int, purpose: str = "Rendering") -> mujoco.Renderer:
    """A ``mujoco.Renderer``, or :class:`RenderUnavailableError` (:func:`open_gl`)."""
    import mujoco  # noqa: PLC0415 - MuJoCo reads MUJOCO_GL at import: after choose_gl_backend

    return open_gl(lambda: mujoco.Renderer(model, height=height, width=width), purpose)


class OverviewRenderer:
    """Renders the arena's ``overview`` camera (robot, table and objects) to RGB."""

    def __init__(self, model: mujoco.MjModel, height: int = 480, width: int = 640, camera: str = "overview"):
        self.model = model
        self.camera = camera
        self._renderer = make_renderer(model, height, width, purpose="env.render()")

    def render(self, data: mujoco.MjData) -> np.ndarray:
        """An ``(H, W, 3)`` uint8 picture of the current state."""
        self._renderer.update_scene(data, camera=self.camera)
        return self._renderer.render().copy()

    def close(self) -> None:
        self._renderer.close()


def render_overview(model: mujoco.MjModel, height: int = 480, width: int = 640) -> OverviewRenderer:
    """An :class:`OverviewRenderer` (raises :class:`RenderUnavailableError` without OpenGL)."""
    return OverviewRenderer(model, height, width)
