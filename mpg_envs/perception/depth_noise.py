"""A depth sensor's noise and missing depth, as an Intel RealSense D400 camera gives them (pure).

Stereo depth cameras measure disparity, so their depth error grows with the square of the
distance: ``std(z) = base_std + quadratic * z**2`` (the D400 series' RMS error is
``z**2 * subpixel / (focal * baseline)``: about 0.0015 / m for a D415, 0.0036 / m for a D435).
They also return no depth (0) at some pixels: along depth edges, where one of the two
imagers does not see the surface, on dark or textureless surfaces that give the stereo
matcher nothing to match, and at scattered pixels.

:func:`corrupt_depth` applies this to a camera's depth image (the camera observation path);
:func:`corrupt_heights` to a top-down heightmap seen by a virtual overhead camera (the
ray-cast path). Both take the random generator they draw from.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

LUMA = np.array([0.299, 0.587, 0.114])
"""ITU-R BT.601 weights of R, G, B in a pixel's brightness (0-255)."""


@dataclass(frozen=True)
class DepthNoise:
    """How noisy and incomplete the depth is (the defaults: a RealSense D415 at under 1 m).

    Attributes:
        base_std: depth noise standard deviation at zero range, metres.
        quadratic: growth of the standard deviation with the square of the depth, 1/m
            (``std(z) = base_std + quadratic * z**2``).
        edge_jump: a pixel is on a depth edge when a 4-neighbour's depth differs by more
            than this (metres), or the neighbour has no depth.
        edge_dropout: probability that an edge pixel reads no depth.
        dark_threshold: a pixel is dark when its brightness (BT.601 luma, 0-255) is below this.
        dark_dropout: probability that a dark pixel reads no depth.
        random_dropout: probability that any other pixel reads no depth.
    """

    base_std: float = 0.0005
    quadratic: float = 0.0015
    edge_jump: float = 0.01
    edge_dropout: float = 0.5
    dark_threshold: float = 25.0
    dark_dropout: float = 0.5
    random_dropout: float = 0.002

    def __post_init__(self) -> None:
        for name in ("base_std", "quadratic", "edge_jump", "dark_threshold"):
            if not np.isfinite(getattr(self, name)) or getattr(self, name) < 0:
                raise ValueError(f"DepthNoise.{name} must be a finite value >= 0, got {getattr(self, name)!r}")
        for name in ("edge_dropout", "dark_dropout", "random_dropout"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"DepthNoise.{name} is a probability in [0, 1], got {getattr(self, name)!r}")

    def to_dict(self) -> dict[str, Any]:
        return {k: float(v) for k, v in asdict(self).items()}


def depth_noise_std(depth: np.ndarray, noise: DepthNoise) -> np.ndarray:
    """Standard deviation (m) of the depth noise at each depth (m): ``base + quadratic z**2``."""
    depth = np.asarray(depth, dtype=np.float64)
    return noise.base_std + noise.quadratic * depth**2


def depth_edges(depth: np.ndarray, jump: float) -> np.ndarray:
    """``(H, W)`` bool: pixels with depth (> 0) whose depth differs by more than ``jump``
    from one of their 4 neighbours, or that have a neighbour without depth (0). Pixels
    without depth are not edges (they have nothing to lose)."""
    depth = np.asarray(depth, dtype=np.float64)
    if depth.ndim != 2:
        raise ValueError(f"depth must be a (H, W) array, got shape {depth.shape}")
    valid = depth > 0
    # Pad with the pixel's own value: the image border is no edge.
    padded = np.pad(depth, 1, mode="edge")
    centre = padded[1:-1, 1:-1]
    edge = np.zeros(depth.shape, dtype=bool)
    for neighbour in (padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2], padded[1:-1, 2:]):
        edge |= (np.abs(neighbour - centre) > jump) | (neighbour <= 0)
    return edge & valid


def dark_pixels(color: np.ndarray, threshold: float) -> np.ndarray:
    """``(H, W)`` bool: pixels of an ``(H, W, 3)`` RGB image whose BT.601 luma is below ``threshold``."""
    color = np.asarray(color)
    if color.ndim != 3 or color.shape[2] != 3:
        raise ValueError(f"color must be a (H, W, 3) RGB array, got shape {color.shape}")
    return color.astype(np.float64) @ LUMA < threshold


def dropout_mask(depth: np.ndarray, color: np.ndarray, noise: DepthNoise, rng: np.random.Generator) -> np.ndarray:
    """``(H, W)`` bool: the pixels that lose their depth (edges, dark pixels, scattered ones),
    each kind with its probability; one uniform draw per pixel."""
    p = np.full(np.shape(depth), noise.random_dropout)
    p = np.where(dark_pixels(color, noise.dark_threshold), np.maximum(p, noise.dark_dropout), p)
    p = np.where(depth_edges(depth, noise.edge_jump), np.maximum(p, noise.edge_dropout), p)
    return rng.random(np.shape(depth)) < p


def corrupt_depth(depth: np.ndarray, color: np.ndarray, noise: DepthNoise, rng: np.random.Generator) -> np.ndarray:
    """A depth image (m, 0 = no depth) as the sensor would return it: Gaussian noise of
    :func:`depth_noise_std` on every valid pixel, then the :func:`dropout_mask` pixels set
    to 0. Pixels without depth stay 0. Returns float32; the inputs are not modified."""
    depth = np.asarray(depth, dtype=np.float64)
    valid = depth > 0
    noisy = depth + rng.standard_normal(depth.shape) * depth_noise_std(depth, noise)
    lost = dropout_mask(depth, color, noise, rng)
    # Noise never turns a reading into "no depth" or a point behind the camera.
    noisy = np.where(valid & ~lost, np.maximum(noisy, 1e-6), 0.0)
    return noisy.astype(np.float32)


def corrupt_heights(
    heights: np.ndarray,
    color: np.ndarray,
    noise: DepthNoise,
    rng: np.random.Generator,
    camera_height: float,
    max_height: float,
) -> tuple[np.ndarray, np.ndarray]:
    """A heightmap (m above the table) as a camera ``camera_height`` m straight above the
    table would see it: noise with the std of depth ``camera_height - h``, heights kept in
    ``[0, max_height]``, and a bool mask of the pixels that lost their depth (their height
    is 0; the caller paints them as it paints unseen pixels). Returns ``(float32 heights, lost)``."""
    heights = np.asarray(heights, dtype=np.float64)
    if not camera_height > max_height:
        raise ValueError(f"camera_height ({camera_height}) must be above max_height ({max_height})")
    depth = camera_height - heights
    noisy = heights + rng.standard_normal(heights.shape) * depth_noise_std(depth, noise)
    lost = dropout_mask(depth, color, noise, rng)
    noisy = np.where(lost, 0.0, np.clip(noisy, 0.0, max_height))
    return noisy.astype(np.float32), lost
