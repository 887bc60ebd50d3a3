"""The replay's plane codec: which encoding each kind of plane gets, and exact round trips."""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from gymnasium import spaces

from mpg_agents.learning.replay_codec import RAW_LIMIT, Frame, PlaneCodec, is_binary_space


def test_each_kind_of_plane_gets_its_encoding_and_decodes_exactly():
    mask = np.zeros((16, 16), np.uint8)
    mask[3:7, 2:9] = 1
    colour = np.arange(256, dtype=np.uint8).reshape(16, 16)
    depth = np.linspace(0.0, 0.3, 256, dtype=np.float32).reshape(16, 16)
    depth[0, 0] = np.float32(1e-38)  # a denormal-adjacent value: kept bit for bit, no float16
    small = np.array([1, 0, 1], np.uint8)
    cases = [
        (PlaneCodec(np.dtype(np.uint8), (16, 16), True), mask, "bits"),
        (PlaneCodec(np.dtype(np.uint8), (16, 16), True), colour, "deflate"),  # not 0/1: the hint alone does not pack
        (PlaneCodec(np.dtype(np.uint8), (16, 16), False), mask, "deflate"),
        (PlaneCodec(np.dtype(np.float32), (16, 16), False), depth, "shuffle"),
        (PlaneCodec(np.dtype(np.uint8), (3,), True), small, "raw"),
    ]
    for codec, value, kind in cases:
        got_kind, blob = codec.encode(value, level=1)
        assert got_kind == kind
        decoded = codec.decode(got_kind, blob)
        assert decoded.dtype == value.dtype and decoded.shape == value.shape
        assert decoded.tobytes() == value.tobytes()
    assert small.nbytes <= RAW_LIMIT < mask.nbytes
    # 256 0/1 values pack into 32 bytes before deflating: the blob is far below the raw 256
    assert len(PlaneCodec(np.dtype(np.uint8), (16, 16), True).encode(mask, 1)[1]) < 64


def test_an_unknown_encoding_is_refused_by_name():
    codec = PlaneCodec(np.dtype(np.uint8), (100,), False)
    with pytest.raises(ValueError, match="unknown plane encoding 'lz4'"):
        codec.decode("lz4", zlib.compress(bytes(100)))


def test_a_frame_counts_its_blob_bytes():
    assert Frame({"a": ("raw", b"abc"), "b": ("deflate", b"12345")}).nbytes == 8


def test_binary_spaces_are_0_1_uint8_boxes_or_multibinary():
    assert is_binary_space(spaces.Box(0, 1, (4, 4), np.uint8))
    assert is_binary_space(spaces.MultiBinary(5))
    assert not is_binary_space(spaces.Box(0, 255, (4, 4), np.uint8))
    assert not is_binary_space(spaces.Box(0.0, 1.0, (4, 4), np.float32))
    assert not is_binary_space(spaces.Discrete(2))
