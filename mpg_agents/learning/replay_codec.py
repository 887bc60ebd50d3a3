"""Exact, lossless compression of observations for the replay buffer (:mod:`mpg_agents.learning.replay`).

Each observation is kept as a :class:`Frame` of compressed planes, one per key; how a key is
stored is its :class:`PlaneCodec`:

- 0/1 uint8 planes (the mask) are bit-packed, then deflated;
- other uint8 planes (colour) are deflated;
- wider dtypes (float32 depth) are byte-shuffled (all first bytes, then all second bytes, ...)
  and deflated, so the slowly varying exponent bytes compress well; decoding restores the
  exact bits, so depth round-trips bit for bit (no float16 quantisation);
- small planes (``occluded``) are stored raw.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

RAW_LIMIT = 64
"""Planes up to this many bytes are cheaper raw than deflated."""


@dataclass(frozen=True)
class PlaneCodec:
    """How one observation key is stored: dtype, shape and encoding ("bits", "deflate", "shuffle", "raw")."""

    dtype: np.dtype
    shape: tuple[int, ...]
    binary_hint: bool

    def encode(self, value: np.ndarray, level: int) -> tuple[str, bytes]:
        """``value`` as ``(encoding, blob)``, deflated at zlib ``level``."""
        arr = np.ascontiguousarray(value, dtype=self.dtype).reshape(self.shape)
        if arr.nbytes <= RAW_LIMIT:
            return "raw", arr.tobytes()
        if self.binary_hint and arr.dtype == np.uint8 and int(arr.max(initial=0)) <= 1:
            return "bits", zlib.compress(np.packbits(arr.reshape(-1)).tobytes(), level)
        if arr.dtype.itemsize == 1:
            return "deflate", zlib.compress(arr.tobytes(), level)
        shuffled = arr.reshape(-1).view(np.uint8).reshape(-1, arr.dtype.itemsize).T
        return "shuffle", zlib.compress(np.ascontiguousarray(shuffled).tobytes(), level)

    def decode(self, kind: str, blob: bytes) -> np.ndarray:
        """Exact inverse of :meth:`encode`."""
        count = int(np.prod(self.shape))
        if kind == "raw":
            return np.frombuffer(blob, dtype=self.dtype).reshape(self.shape).copy()
        data = zlib.decompress(blob)
        if kind == "bits":
            return np.unpackbits(np.frombuffer(data, np.uint8), count=count).astype(self.dtype).reshape(self.shape)
        if kind == "deflate":
            return np.frombuffer(data, dtype=self.dtype).reshape(self.shape).copy()
        if kind == "shuffle":
            planes = np.frombuffer(data, np.uint8).reshape(self.dtype.itemsize, count)
            return np.ascontiguousarray(planes.T).view(self.dtype).reshape(self.shape)
        raise ValueError(f"unknown plane encoding {kind!r}")


class Frame:
    """One stored observation: an encoded blob per key."""

    __slots__ = ("planes", "nbytes")

    def __init__(self, planes: dict[str, tuple[str, bytes]]) -> None:
        self.planes = planes
        self.nbytes = sum(len(blob) for _, blob in planes.values())


def is_binary_space(space: spaces.Space) -> bool:
    """A uint8 Box with bounds 0..1 (the mask) or a MultiBinary space: its planes may be bit-packed."""
    if isinstance(space, spaces.MultiBinary):
        return True
    return (
        isinstance(space, spaces.Box)
        and np.dtype(space.dtype) == np.uint8
        and bool(np.all(space.low == 0))
        and bool(np.all(space.high == 1))
    )
