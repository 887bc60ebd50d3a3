"""MPGNet agents: the move/push/grasp Q-networks, their SB3 policy, replay and training step.

Public entry points:

- :class:`MPGNet` / :class:`MPGNetConfig` (``mpg_agents.mpgnet``): the three-branch network.
- :class:`MPGNetPolicy` (``mpg_agents.policy``): ``stable_baselines3.DQN(MPGNetPolicy, env)``.
- :class:`MPGDQN` (``mpg_agents.dqn``): DQN with double-DQN targets and surprise priorities.
- :class:`PrioritizedHeightmapReplayBuffer` (``mpg_agents.replay``): compact SB3 replay buffer.
- :func:`save_qmap_png` (``mpg_agents.visualize``): Q-map pictures.
"""

from mpg_agents.dqn import MPGDQN, td_targets
from mpg_agents.mobilenet import MobileNetV3Features, load_torchvision_features
from mpg_agents.mpgnet import (
    MPGNet,
    MPGNetConfig,
    flat_q,
    load_mpgnet,
    recompute_batch_norm_statistics,
    save_mpgnet,
)
from mpg_agents.policy import COORDINATIONS, Decision, GraspScorer, MPGNetPolicy, MPGQNetwork
from mpg_agents.replay import PrioritizedHeightmapReplayBuffer
from mpg_agents.visualize import save_qmap_png

__all__ = [
    "COORDINATIONS",
    "Decision",
    "GraspScorer",
    "MPGDQN",
    "MPGNet",
    "MPGNetConfig",
    "MPGNetPolicy",
    "MPGQNetwork",
    "MobileNetV3Features",
    "PrioritizedHeightmapReplayBuffer",
    "flat_q",
    "load_mpgnet",
    "load_torchvision_features",
    "recompute_batch_norm_statistics",
    "save_mpgnet",
    "save_qmap_png",
    "td_targets",
]
