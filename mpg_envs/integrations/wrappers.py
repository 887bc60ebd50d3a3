"""Standard observation and action wrappers, so off-the-shelf RL code runs on the MPG envs.

The raw envs speak the paper's language: a ``Dict`` of 224 x 224 heightmaps and a flat
``Discrete(P * 16 * 224 * 224)`` pixel-wise action (802,816 actions on Stage II). Generic
algorithms (SB3's ``CnnPolicy``, RLlib's default models, CleanRL scripts) want one image and
a small action space. These wrappers give them that, and compose with each other and with
Gymnasium's own wrappers::

    env = ImageObservation(GridAction(gym.make("MPG-Stage2-v0")))
    model = stable_baselines3.PPO("CnnPolicy", env)        # 4.9M parameters

SB3's DQN keeps 1M transitions by default: at 84 x 84 x 5 bytes an image that is 35 GB, so
give it ``buffer_size=10_000`` (and ``optimize_memory_usage=True``, 350 MB), as
``benchmarks/third_party.py`` does.

- :class:`ImageObservation`: one ``uint8`` image, colour, depth and mask as channels.
- :class:`GridAction`: ``Discrete(P x rotations x cells)``, each cell's centre pixel.
- :class:`ContinuousAction`: ``Box(-1, 1, (3 + P,))`` for PPO/SAC/TD3.

Every wrapper keeps the env's ``info`` untouched (``info["occluded"]``, ``is_success`` ...),
so the paper's metrics are computed the same way on wrapped and raw envs.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import cv2
import gymnasium as gym
import numpy as np
from gymnasium import spaces

from mpg_envs.grid.actions import PixelAction, encode_action
from mpg_envs.grid.primitive_specs import PAPER_PRIMITIVES, half_turn_symmetric
from mpg_envs.grid.workspace import NUM_ROTATIONS, _is_int

IMAGE_CHANNELS = ("red", "green", "blue", "depth", "mask")
"""The planes of :class:`ImageObservation`'s image, in order (plus ``occluded`` when asked)."""

DEFAULT_IMAGE_SIZE = 84
"""Default side of the wrapped image. SB3's ``NatureCNN`` on 224 x 224 alone holds 18.9M
parameters; at 84 x 84 (the Atari convention) it holds 1.7M, which keeps
``PPO("CnnPolicy", ImageObservation(GridAction(env)))`` on Stage II under 5M."""

SYMMETRIC_PRIMITIVES = tuple(p for p in PAPER_PRIMITIVES if half_turn_symmetric(p))
"""The paper's primitives whose rotation k and k + 8 are the same motion (move and grasp: a
parallel-jaw grasp closes along a line; each record's ``half_turn_symmetric``). Push is
directional: its rotations span the full 360 degrees."""


# ----------------------------------------------------------------------------- observations
def quantise_depth(depth: np.ndarray, z_max: float) -> np.ndarray:
    """Heights in metres -> ``uint8`` levels: ``round(255 * depth / z_max)``.

    With the default workspace (``z_max`` = 0.4 m) one level is 0.4 / 255 = 1.57 mm.
    Heights outside ``[0, z_max]`` are an error, never clipped.
    """
    depth = np.asarray(depth, dtype=np.float32)
    if not z_max > 0:
        raise ValueError(f"z_max must be positive, got {z_max!r}")
    if depth.size and (not np.isfinite(depth).all() or depth.min() < 0 or depth.max() > z_max * (1 + 1e-6)):
        raise ValueError(f"depth must lie in [0, {z_max}] m, got values in [{depth.min()}, {depth.max()}]")
    return np.rint(np.minimum(depth, z_max) * (255.0 / z_max)).astype(np.uint8)  # minimum: float error only


def image_from_observation(
    obs: Mapping[str, np.ndarray],
    size: int,
    z_max: float,
    channels_last: bool = False,
    occlusion_channel: bool = False,
) -> np.ndarray:
    """The ``(C, size, size)`` (or ``(size, size, C)``) ``uint8`` image of an MPG observation.

    Planes: red, green, blue (as observed), depth (:func:`quantise_depth`), mask (0 or 255)
    and, with ``occlusion_channel``, a constant plane of 255 while the target is occluded.
    Resizing uses ``cv2.INTER_AREA`` for colour and depth (an average over each output pixel)
    and nearest neighbour for the mask (it stays binary).
    """
    color = np.asarray(obs["color"], dtype=np.uint8)
    height, width = color.shape[:2]
    planes: np.ndarray = np.empty((height, width, 4), np.uint8)
    planes[..., :3] = color
    planes[..., 3] = quantise_depth(obs["depth"], z_max)
    mask: np.ndarray = (np.asarray(obs["mask"]) > 0).astype(np.uint8) * np.uint8(255)
    if (height, width) != (size, size):
        planes = cv2.resize(planes, (size, size), interpolation=cv2.INTER_AREA)
        mask = cv2.resize(mask, (size, size), interpolation=cv2.INTER_NEAREST)
    stack = [planes, mask[..., None]]
    if occlusion_channel:
        stack.append(np.full((size, size, 1), 255 * int(np.asarray(obs["occluded"]).reshape(-1)[0]), np.uint8))
    image = np.concatenate(stack, axis=-1)
    return image if channels_last else np.ascontiguousarray(image.transpose(2, 0, 1))


class ImageObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """One ``Box(0, 255, (C, size, size), uint8)`` image instead of the ``Dict`` of heightmaps.

    ``C`` = 5: red, green, blue, depth, mask (:data:`IMAGE_CHANNELS`). Depth is quantised
    over the workspace's height range, ``round(255 * z / z_max)``: 1.57 mm per level with
    the default 0.4 m. The mask is 0 or 255. ``size`` < 224 shrinks the 2 mm heightmap
    grid (84: 5.3 mm per pixel); the action wrappers still address the full 224 grid.

    The occlusion flag is not an image: it stays in ``info["occluded"]`` (reset and every
    step). ``occlusion_channel=True`` adds it as a sixth, constant plane (255 = occluded)
    for policies that can only see the image (Stages III, V and the test scenes use it).

    ``channels_last=True`` gives ``(size, size, C)``, the layout RLlib's CNN encoder wants;
    SB3 takes either (``VecTransposeImage`` turns channels-last images around).
    """

    def __init__(
        self,
        env: gym.Env,
        size: int = DEFAULT_IMAGE_SIZE,
        occlusion_channel: bool = False,
        channels_last: bool = False,
    ):
        # Recorded so env.spec (and gymnasium's checker) can rebuild the wrapped env.
        gym.utils.RecordConstructorArgs.__init__(
            self, size=size, occlusion_channel=occlusion_channel, channels_last=channels_last
        )
        gym.ObservationWrapper.__init__(self, env)
        source = env.observation_space
        if not isinstance(source, spaces.Dict) or not {"color", "depth", "mask", "occluded"} <= set(source.spaces):
            exemplar = isinstance(source, spaces.Dict) and "query_color" in source.spaces
            why = "; an env naming its target by an exemplar (target_spec='exemplar') has no mask" if exemplar else ""
            raise ValueError(
                f"ImageObservation needs the MPG Dict observation (color, depth, mask, occluded), got {source}{why}"
            )
        if not _is_int(size) or not 8 <= size <= 1024:
            raise ValueError(f"size must be an integer in 8..1024, got {size!r}")
        self.size = int(size)
        depth_space: Any = source["depth"]  # a Box
        self.z_max = float(depth_space.high.max())
        self.occlusion_channel = bool(occlusion_channel)
        self.channels_last = bool(channels_last)
        channels = len(IMAGE_CHANNELS) + int(self.occlusion_channel)
        shape = (self.size, self.size, channels) if self.channels_last else (channels, self.size, self.size)
        self.observation_space = spaces.Box(0, 255, shape, np.uint8)

    def observation(self, observation: Mapping[str, np.ndarray]) -> np.ndarray:
        return image_from_observation(observation, self.size, self.z_max, self.channels_last, self.occlusion_channel)


# ----------------------------------------------------------------------------- actions
def _check_grid(size: int, cell: int, rotations: int) -> None:
    if not _is_int(cell) or cell < 1 or size % cell:
        divisors = [d for d in range(1, size + 1) if size % d == 0]
        raise ValueError(
            f"cell must be a whole number of pixels dividing the {size}-pixel heightmap, one of {divisors}; got {cell!r}"
        )
    if not _is_int(rotations) or rotations < 1 or NUM_ROTATIONS % rotations:
        divisors = [d for d in range(1, NUM_ROTATIONS + 1) if NUM_ROTATIONS % d == 0]
        raise ValueError(f"rotations must divide the env's {NUM_ROTATIONS} rotations, one of {divisors}; got {rotations!r}")


def grid_rotation(primitive: str, r: int, rotations: int) -> int:
    """The env's rotation index (0..15, 22.5 degrees apart) of grid rotation ``r``.

    Move and grasp are symmetric mod 180 degrees, so with ``rotations`` <= 8 their grid
    rotations spread over 180 degrees (``k = r * 8 / rotations``); push is not, so its
    spread over 360 degrees (``k = r * 16 / rotations``). With 16 every primitive uses all
    16 (grasp's k and k + 8 are then the same motion).
    """
    half = NUM_ROTATIONS // 2
    if half_turn_symmetric(primitive) and rotations <= half:
        return r * (half // rotations)
    return r * (NUM_ROTATIONS // rotations)


def grid_to_pixel_action(index: int, primitives: tuple[str, ...], cell: int, rotations: int, size: int) -> PixelAction:
    """Decode a :class:`GridAction` index (C order over primitive, rotation, cell row,
    cell column) to the env's ``(primitive, rotation, row, col)``: the pixel at the cell's
    centre, ``cell_row * cell + cell // 2``."""
    cells = size // cell
    n = len(primitives) * rotations * cells * cells
    if isinstance(index, np.ndarray) and index.size == 1:
        index = index.reshape(())[()]
    if not _is_int(index) or not 0 <= int(index) < n:
        raise ValueError(
            f"action must be an integer in 0..{n - 1} (primitives {primitives}, "
            f"{rotations} rotations, {cells}x{cells} cells), got {index!r}"
        )
    p, rest = divmod(int(index), rotations * cells * cells)
    r, rest = divmod(rest, cells * cells)
    cell_row, cell_col = divmod(rest, cells)
    primitive = primitives[p]
    return PixelAction(
        primitive, grid_rotation(primitive, r, rotations), cell_row * cell + cell // 2, cell_col * cell + cell // 2
    )


class GridAction(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """``Discrete(P x rotations x (224 / cell)^2)``: a coarse pixel-wise action.

    Index order is C order over (primitive, rotation, cell row, cell column); primitives
    in the env's order (``env.unwrapped.primitives``). Each index acts at the centre pixel
    of its ``cell`` x ``cell`` block; rotations map as :func:`grid_rotation` says.

    The defaults (8-pixel = 16 mm cells, 8 rotations) give 6,272 actions per primitive:
    Stage II's PPO ``CnnPolicy`` head is 3.2M parameters; Stage V (three primitives) has
    18,816 actions, a 9.6M head: use ``cell=16`` (1,568 per primitive) to stay small there.
    """

    def __init__(self, env: gym.Env, cell: int = 8, rotations: int = 8):
        gym.utils.RecordConstructorArgs.__init__(self, cell=cell, rotations=rotations)
        gym.ActionWrapper.__init__(self, env)
        base = env.unwrapped.action_space
        self.size = int(getattr(base, "size", 0))
        if not hasattr(base, "primitives") or self.size < 1:
            raise ValueError(f"GridAction needs an MPG env (a PixelActionSpace), got {base!r}")
        _check_grid(self.size, cell, rotations)
        self.primitives: tuple[str, ...] = tuple(base.primitives)
        self.cell, self.rotations = int(cell), int(rotations)
        self.cells = self.size // self.cell
        self.action_space = spaces.Discrete(len(self.primitives) * self.rotations * self.cells**2)

    def decode(self, action: Any) -> PixelAction:
        """The env's ``(primitive, rotation, row, col)`` of a grid action."""
        return grid_to_pixel_action(action, self.primitives, self.cell, self.rotations, self.size)

    def action(self, action: Any) -> int:
        return encode_action(self.primitives, *self.decode(action), size=self.size)


def continuous_to_pixel_action(action: np.ndarray, primitives: tuple[str, ...], size: int) -> PixelAction:
    """Decode a :class:`ContinuousAction` vector ``(x, y, angle, score_1..score_P)``.

    ``x`` -> column and ``y`` -> row: ``[-1, 1]`` is cut into ``size`` equal bins, one per
    pixel, ``floor((v + 1) / 2 * size)`` (``v`` = 1 falls in the last). ``angle`` -> rotation
    ``round((angle + 1) * 8) mod 16``, the nearest of 16 steps of 22.5 degrees over
    ``[-1, 1]`` = 0..360 degrees. The primitive is the one with the largest score (the
    first on a tie). Values outside ``[-1, 1]`` or not finite are an error.
    """
    a = np.asarray(action, dtype=np.float64)
    expected = (3 + len(primitives),)
    if a.shape != expected:
        raise ValueError(
            f"action must have shape {expected} (x, y, angle, one score per primitive of {primitives}), got {a.shape}"
        )
    if not np.isfinite(a).all() or np.abs(a).max() > 1.0 + 1e-6:
        raise ValueError(f"action values must be finite and in [-1, 1], got {a.tolist()}")
    x, y, angle = np.clip(a[:3], -1.0, 1.0)  # float error only: checked above
    col = min(int((x + 1.0) / 2.0 * size), size - 1)
    row = min(int((y + 1.0) / 2.0 * size), size - 1)
    rotation = int(np.rint((angle + 1.0) * NUM_ROTATIONS / 2.0)) % NUM_ROTATIONS
    return PixelAction(primitives[int(np.argmax(a[3:]))], rotation, row, col)


class ContinuousAction(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """``Box(-1, 1, (3 + P,), float32)``: ``x``, ``y``, ``angle`` and one score per primitive.

    The largest score picks the primitive; ``x``/``y`` pick the pixel (rounded to the
    pixel whose bin holds them) and ``angle`` the nearest of the 16 rotations, as
    :func:`continuous_to_pixel_action` says. For PPO, SAC and TD3 (SB3 clips or squashes
    their actions into the box; anything outside it raises here).
    """

    def __init__(self, env: gym.Env):
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ActionWrapper.__init__(self, env)
        base = env.unwrapped.action_space
        self.size = int(getattr(base, "size", 0))
        if not hasattr(base, "primitives") or self.size < 1:
            raise ValueError(f"ContinuousAction needs an MPG env (a PixelActionSpace), got {base!r}")
        self.primitives: tuple[str, ...] = tuple(base.primitives)
        self.action_space = spaces.Box(-1.0, 1.0, (3 + len(self.primitives),), np.float32)

    def decode(self, action: Any) -> PixelAction:
        """The env's ``(primitive, rotation, row, col)`` of a continuous action."""
        return continuous_to_pixel_action(action, self.primitives, self.size)

    def action(self, action: Any) -> int:
        return encode_action(self.primitives, *self.decode(action), size=self.size)


__all__ = [
    "DEFAULT_IMAGE_SIZE",
    "IMAGE_CHANNELS",
    "ContinuousAction",
    "GridAction",
    "ImageObservation",
    "continuous_to_pixel_action",
    "grid_rotation",
    "grid_to_pixel_action",
    "image_from_observation",
    "quantise_depth",
]
