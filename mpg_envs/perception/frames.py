"""Offscreen frames of a MuJoCo scene for the camera observation path: a colour frame, and
depth with segmentation read from one rendering pass (``mujoco.Renderer`` renders the
segmentation pass twice to give both, and the colour pass is the third).

Needs OpenGL (see :mod:`mpg_envs.perception.render`); images follow the image convention of
``mujoco.Renderer``: row 0 at the top, depth in metres along the optical axis.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mpg_envs.perception.render import open_gl


def linear_depth(zbuffer: np.ndarray, near: float, far: float) -> np.ndarray:
    """Metres along the optical axis from MuJoCo's reversed-Z depth buffer (``mjDEPTH_ZEROFAR``)
    of a perspective camera with clipping planes ``near`` and ``far``; the same float32
    arithmetic as ``mujoco.Renderer``, so the two agree exactly."""
    zfar, znear = np.float32(far), np.float32(near)
    c_coef = -(zfar + znear) / (zfar - znear)
    d_coef = -(np.float32(2) * zfar * znear) / (zfar - znear)
    c_coef = np.float32(-0.5) * c_coef - np.float32(0.5)
    d_coef = np.float32(-0.5) * d_coef
    return (d_coef / (np.asarray(zbuffer).astype(np.float64) + c_coef)).astype(np.float32)


class SceneFrames:
    """Renders ``scene`` (update it with :meth:`update`, then edit it) offscreen.

    Raises:
        RenderUnavailableError: (a ``RuntimeError``) when no OpenGL context can be created.
        ValueError: when the image is larger than the model's offscreen framebuffer.
    """

    def __init__(self, model: mujoco.MjModel, height: int, width: int, purpose: str = "Rendering") -> None:
        glob = model.vis.global_
        if width > glob.offwidth or height > glob.offheight:
            raise ValueError(
                f"image {width} x {height} is larger than the model's offscreen framebuffer "
                f"{glob.offwidth} x {glob.offheight}: raise <visual><global offwidth/offheight> (add_cameras does)"
            )
        self.model = model
        self.height, self.width = int(height), int(width)
        self.scene = mujoco.MjvScene(model, maxgeom=10000)
        self._gl, self._context = open_gl(lambda: self._open(width, height), purpose)
        self._rect = mujoco.MjrRect(0, 0, self.width, self.height)
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._rgb = np.empty((self.height, self.width, 3), dtype=np.uint8)
        self._zbuffer = np.empty((self.height, self.width), dtype=np.float32)
        extent = model.stat.extent
        self._near, self._far = model.vis.map.znear * extent, model.vis.map.zfar * extent

    def _open(self, width: int, height: int):
        gl = mujoco.GLContext(width, height)
        gl.make_current()
        context = mujoco.MjrContext(self.model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, context)
        context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        return gl, context

    def update(self, data: mujoco.MjData, camera_id: int, option: mujoco.MjvOption) -> None:
        """Fill ``scene`` with ``data``'s state seen from fixed camera ``camera_id``."""
        self._camera.fixedcamid = camera_id
        mujoco.mjv_updateScene(self.model, data, option, None, self._camera, mujoco.mjtCatBit.mjCAT_ALL, self.scene)

    def _render(self, rgb: np.ndarray, zbuffer: np.ndarray | None) -> None:
        if self._context is None:
            raise RuntimeError("SceneFrames is closed")
        self._gl.make_current()
        mujoco.mjr_render(self._rect, self.scene, self._context)
        mujoco.mjr_readPixels(rgb, zbuffer, self._rect, self._context)

    def color(self) -> np.ndarray:
        """``(H, W, 3)`` uint8 RGB of the scene as lit."""
        self._render(self._rgb, None)
        return np.flipud(self._rgb).copy()  # OpenGL's first row is the bottom one

    def depth_and_segmentation(self) -> tuple[np.ndarray, np.ndarray]:
        """``(depth, geom_id)`` from one segmentation pass: ``(H, W)`` float32 metres along the
        optical axis, and ``(H, W)`` int32 id of the geom seen at each pixel (-1: none)."""
        flags = self.scene.flags.copy()
        self.scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = 1
        self.scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = 1
        try:
            self._render(self._rgb, self._zbuffer)
        finally:
            np.copyto(self.scene.flags, flags)
        rgb = self._rgb.astype(np.int32)
        segid = rgb[..., 0] | (rgb[..., 1] << 8) | (rgb[..., 2] << 16)
        lookup = np.full(self.scene.ngeom + 1, -1, dtype=np.int32)  # segid 0: nothing drawn
        for geom in self.scene.geoms[: self.scene.ngeom]:
            if geom.segid >= 0 and geom.objtype == mujoco.mjtObj.mjOBJ_GEOM:
                lookup[geom.segid + 1] = geom.objid
        geom_id = np.where(segid <= self.scene.ngeom, lookup[np.minimum(segid, self.scene.ngeom)], -1).astype(np.int32)
        depth = linear_depth(self._zbuffer, self._near, self._far)
        return np.flipud(depth).copy(), np.flipud(geom_id).copy()

    def close(self) -> None:
        """Release the OpenGL context (idempotent)."""
        if self._context is not None:
            self._context.free()
            self._context = None
        if self._gl is not None:
            self._gl.free()
            self._gl = None
