"""Fixtures for the agent tests: small-variant nets, scenes and batch-norm calibration."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from mpg_agents.network.mpgnet import MPGNet, recompute_batch_norm_statistics
from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_agents.sb3 import MPGNetPolicy

from .fake_env import random_scene


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


TINY = {"net_config": {"trunk_depth": 4}}
"""A cheap network: small trunks cut after features.3 (output stride 8)."""


@pytest.fixture(scope="session")
def build_policy():
    """Factory ``(observation_space, action_space, **kwargs) -> MPGNetPolicy``: the tiny net,
    seeded, as the policy and env tests build it."""

    def build(observation_space, action_space, **kwargs) -> MPGNetPolicy:
        torch.manual_seed(0)
        return MPGNetPolicy(observation_space, action_space, lambda _: 1e-4, **{**TINY, **kwargs})

    return build
