"""MPGNet agents: the move/push/grasp Q-networks, the agent acting with them, its training and
its Stable-Baselines3 adapter.

Public entry points (``ARCHITECTURE.md`` maps every module):

- :class:`MPGNet` (``mpg_agents.network.mpgnet``) / :class:`MPGNetConfig` (``mpg_agents.network.mpgnet_config``):
  the three-branch network; ``save_mpgnet`` / ``load_mpgnet`` (``mpg_agents.acting.weights``).
- :class:`MPGAgent` (``mpg_agents.acting.agent``): the network deciding with :func:`choose_primitive`
  (``mpg_agents.acting.coordination``) and Q*_g (:class:`GraspThreshold`, ``mpg_agents.acting.grasp_threshold``).
- :class:`MPGNetPolicy` / :class:`MPGDQN` (``mpg_agents.sb3``): ``stable_baselines3.DQN(MPGNetPolicy, env)``,
  and SB3's DQN training with :func:`td_step` (``mpg_agents.learning.td_step``).
- :class:`PrioritizedHeightmapReplayBuffer` (``mpg_agents.learning.replay``): compact SB3 replay buffer.
- :data:`TRAINING_STAGES` (``mpg_agents.learning.training_stages``): the paper's stages as data.
- :func:`save_qmap_png` (``mpg_agents.evaluation.visualize``): Q-map pictures.
"""

import importlib

from mpg_envs._version import __version__  # one version for both packages
from mpg_envs.threads import use_passive_openmp_wait

# Before torch loads OpenMP: idle threads sleep, not spin, so runs side by side share the cores.
use_passive_openmp_wait()

# The public names load on first use (PEP 562), so ``mpg-eval --help`` and argument errors do not
# wait for torch, and only the SB3 adapter's names import Stable-Baselines3.
_LAZY = {
    "COORDINATIONS": "mpg_agents.acting.coordination",
    "Decision": "mpg_agents.acting.decision",
    "Discriminator": "mpg_agents.acting.discriminator",
    "GraspThreshold": "mpg_agents.acting.grasp_threshold",
    "MPGAgent": "mpg_agents.acting.agent",
    "MPGDQN": "mpg_agents.sb3",
    "MPGNet": "mpg_agents.network.mpgnet",
    "MPGNetConfig": "mpg_agents.network.mpgnet_config",
    "MPGNetPolicy": "mpg_agents.sb3",
    "MPGQFunction": "mpg_agents.acting.q_function",
    "MPGQNetwork": "mpg_agents.sb3",
    "MobileNetV3Features": "mpg_agents.network.mobilenet",
    "PrioritizedHeightmapReplayBuffer": "mpg_agents.learning.replay",
    "TDStepConfig": "mpg_agents.learning.td_step",
    "TRAINING_STAGES": "mpg_agents.learning.training_stages",
    "TrainConfig": "mpg_agents.learning.train_config",
    "TrainingStage": "mpg_agents.learning.training_stages",
    "calibrate_q_star": "mpg_agents.acting.grasp_threshold",
    "choose_primitive": "mpg_agents.acting.coordination",
    "flat_q": "mpg_agents.network.mpgnet",
    "load_mpgnet": "mpg_agents.acting.weights",
    "load_torchvision_features": "mpg_agents.network.mobilenet",
    "recompute_batch_norm_statistics": "mpg_agents.network.mpgnet",
    "save_mpgnet": "mpg_agents.acting.weights",
    "save_qmap_png": "mpg_agents.evaluation.visualize",
    "td_step": "mpg_agents.learning.td_step",
    "td_targets": "mpg_agents.learning.td_step",
}


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'mpg_agents' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "__version__",
    "COORDINATIONS",
    "Decision",
    "Discriminator",
    "GraspThreshold",
    "MPGAgent",
    "MPGDQN",
    "MPGNet",
    "MPGNetConfig",
    "MPGNetPolicy",
    "MPGQFunction",
    "MPGQNetwork",
    "MobileNetV3Features",
    "PrioritizedHeightmapReplayBuffer",
    "TDStepConfig",
    "TRAINING_STAGES",
    "TrainConfig",
    "TrainingStage",
    "calibrate_q_star",
    "choose_primitive",
    "flat_q",
    "load_mpgnet",
    "load_torchvision_features",
    "recompute_batch_norm_statistics",
    "save_mpgnet",
    "save_qmap_png",
    "td_step",
    "td_targets",
]
