"""The network's finger masks use the geometry of the env it acts on, and the network layer
imports no MuJoCo."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
import torch

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_agents.acting.agent import MPGAgent
from mpg_agents.acting.spaces import finger_geometry
from mpg_agents.network.finger_geometry import FingerGeometry
from mpg_agents.network.mpgnet import MPGNet
from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_agents.network.regions import least_blocked
from mpg_envs.grid.grasp_geometry import fingers_blocked
from mpg_envs.grid.workspace import Workspace
from mpg_envs.simulation.primitives import PrimitiveConfig
from mpg_envs.tasks.config import EnvConfig

from .fake_env import random_scene

# A wider table seen at 2.5 mm per pixel (still 224 x 224), and a shallower grasp.
WIDE = Workspace(x_min=0.22, x_max=0.78, y_min=-0.28, y_max=0.28, resolution=0.0025)
SHALLOW = PrimitiveConfig(grasp_depth=0.03, grasp_min_height=0.015)
NET = {"trunk_depth": 2, "grasp_fingers": "clear", "grasp_region": "target"}


def test_the_network_modules_import_no_mujoco():
    code = (
        "import sys, mpg_agents.network.mpgnet, mpg_agents.network.primitive_net, mpg_agents.network.regions, "
        "mpg_agents.network.finger_geometry, mpg_agents.network.inputs, mpg_agents.network.rotations; "
        "print('mujoco' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_an_env_with_another_workspace_gives_matching_finger_masks(rng):
    env = gym.make("MPG-Stage2-v0", config=EnvConfig(workspace=WIDE, primitives=SHALLOW))
    try:
        geometry = finger_geometry(env)
        assert geometry == FingerGeometry(WIDE, 0.03, 0.015)
        assert finger_geometry(gym.make("MPG-Stage2-v0")) == finger_geometry() == FingerGeometry(Workspace(), 0.04, 0.02)
        agent = MPGAgent.build(env.observation_space, env.action_space, net_config=NET, geometry=geometry)
        scene = random_scene(rng, occluded=False)
        prep = agent.q_net.mpgnet.prepare({k: torch.as_tensor(v)[None] for k, v in scene.items()})
        blocked = torch.from_numpy(fingers_blocked(scene["depth"], 0.0025, 0.03, 0.015))[None]
        assert torch.equal(prep.grasp_fingers, least_blocked(blocked, prep.grasp_region, agent.net_config.finger_tolerance_m))
        default = torch.from_numpy(fingers_blocked(scene["depth"], 0.002, 0.04, 0.02))[None]
        assert not torch.equal(prep.grasp_fingers, least_blocked(default, prep.grasp_region, agent.net_config.finger_tolerance_m))
    finally:
        env.close()


def test_finger_masks_need_a_geometry_of_the_network_size():
    cfg = MPGNetConfig.small(**NET)
    with pytest.raises(ValueError, match="FingerGeometry"):
        MPGNet(cfg)
    with pytest.raises(ValueError, match="224 x 224"):
        MPGNet(cfg, FingerGeometry(Workspace(resolution=0.004), 0.04, 0.02))
    assert MPGNet(MPGNetConfig.small(trunk_depth=2)).geometry is None  # no finger masks: no geometry needed
    assert np.isclose(FingerGeometry(WIDE, 0.03, 0.015).workspace.resolution, 0.0025)
