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

from mpg_agents.coordination import COORDINATIONS, choose_primitive  # noqa: E402
from mpg_agents.dqn import MPGDQN  # noqa: E402
from mpg_agents.grasp_scorer import GraspScorer  # noqa: E402
from mpg_agents.mobilenet import MobileNetV3Features, load_torchvision_features  # noqa: E402
from mpg_agents.mpgnet import MPGNet, flat_q, recompute_batch_norm_statistics  # noqa: E402
from mpg_agents.mpgnet_config import MPGNetConfig  # noqa: E402
from mpg_agents.policy import Decision, MPGNetPolicy, MPGQNetwork  # noqa: E402
from mpg_agents.replay import PrioritizedHeightmapReplayBuffer  # noqa: E402
from mpg_agents.td_step import TDStepConfig, td_step, td_targets  # noqa: E402
from mpg_agents.training_stages import TRAINING_STAGES, TrainingStage  # noqa: E402
from mpg_agents.visualize import save_qmap_png  # noqa: E402
from mpg_agents.weights import load_mpgnet, save_mpgnet  # noqa: E402

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
