"""Fixtures for the agent tests: small-variant nets, scenes and batch-norm calibration."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from mpg_agents.mpgnet import MPGNet, MPGNetConfig, recompute_batch_norm_statistics

from .scenes import random_scene


@pytest.fixture(autouse=True)
def _two_threads():
    torch.set_num_threads(2)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


@pytest.fixture
def scene(rng) -> dict[str, np.ndarray]:
    return random_scene(rng, occluded=False)


def calibrate_bn(net: torch.nn.Module, obs: dict, forward=None) -> None:
    """Realistic BN statistics for an untrained net (flat Q maps otherwise); see the library helper."""
    recompute_batch_norm_statistics(net, forward or net, obs)


@pytest.fixture(scope="module")
def small_net() -> MPGNet:
    """An all-branch small MPGNet with calibrated batch norm, in eval mode."""
    torch.manual_seed(0)
    net = MPGNet(MPGNetConfig.small())
    calibrate_bn(net, random_scene(np.random.default_rng(7), occluded=False))
    return net
