"""MPGNet agents: the move/push/grasp Q-networks, their SB3 policy, replay and training step.

Public entry points (``ARCHITECTURE.md`` maps every module):

- :class:`MPGNet` (``mpg_agents.mpgnet``) / :class:`MPGNetConfig` (``mpg_agents.mpgnet_config``):
  the three-branch network; ``save_mpgnet`` / ``load_mpgnet`` (``mpg_agents.weights``).
- :class:`MPGNetPolicy` (``mpg_agents.policy``): ``stable_baselines3.DQN(MPGNetPolicy, env)``,
  deciding with :func:`choose_primitive` (``mpg_agents.coordination``).
- :class:`MPGDQN` (``mpg_agents.dqn``): SB3 DQN training with :func:`td_step` (``mpg_agents.td_step``).
- :class:`PrioritizedHeightmapReplayBuffer` (``mpg_agents.replay``): compact SB3 replay buffer.
- :data:`TRAINING_STAGES` (``mpg_agents.training_stages``): the paper's stages as data.
- :func:`save_qmap_png` (``mpg_agents.visualize``): Q-map pictures.
"""

from mpg_envs.threads import use_passive_openmp_wait

use_passive_openmp_wait()  # before torch loads OpenMP: idle threads sleep, not spin (issue 12)

# The public names load on first use (PEP 562), so ``mpg-eval --help`` and argument errors do not
# wait for torch and Stable-Baselines3 to import.
_LAZY = {
    'COORDINATIONS': 'mpg_agents.coordination',
    'Decision': 'mpg_agents.policy',
    'GraspScorer': 'mpg_agents.grasp_scorer',
    'MPGDQN': 'mpg_agents.dqn',
    'MPGNet': 'mpg_agents.mpgnet',
    'MPGNetConfig': 'mpg_agents.mpgnet_config',
    'MPGNetPolicy': 'mpg_agents.policy',
    'MPGQNetwork': 'mpg_agents.policy',
    'MobileNetV3Features': 'mpg_agents.mobilenet',
    'PrioritizedHeightmapReplayBuffer': 'mpg_agents.replay',
    'TDStepConfig': 'mpg_agents.td_step',
    'TRAINING_STAGES': 'mpg_agents.training_stages',
    'TrainingStage': 'mpg_agents.training_stages',
    'choose_primitive': 'mpg_agents.coordination',
    'flat_q': 'mpg_agents.mpgnet',
    'load_mpgnet': 'mpg_agents.weights',
    'load_torchvision_features': 'mpg_agents.mobilenet',
    'recompute_batch_norm_statistics': 'mpg_agents.mpgnet',
    'save_mpgnet': 'mpg_agents.weights',
    'save_qmap_png': 'mpg_agents.visualize',
    'td_step': 'mpg_agents.td_step',
    'td_targets': 'mpg_agents.td_step',
}


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'mpg_agents' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


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
    "TDStepConfig",
    "TRAINING_STAGES",
    "TrainingStage",
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
