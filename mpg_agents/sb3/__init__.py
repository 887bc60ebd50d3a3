"""Stable-Baselines3 adapter of the MPGNet agent: the only part of ``mpg_agents`` built on SB3's
policy, algorithm and buffer classes.

- :class:`MPGNetPolicy`: ``stable_baselines3.DQN(MPGNetPolicy, env)`` runs on every MPG env;
  it decides as :class:`~mpg_agents.acting.agent.MPGAgent` does.
- :class:`MPGQNetwork`: its Q-network, :class:`~mpg_agents.acting.q_function.MPGQFunction` as SB3's
  ``QNetwork``.
- :class:`MPGDQN`: SB3's DQN whose gradient step is ``mpg-train``'s
  (:func:`~mpg_agents.learning.td_step.td_step`), with ``mpg-train``'s settings as its defaults
  (:class:`~mpg_agents.learning.train_config.TrainConfig`).
- :class:`SB3HeightmapReplayBuffer`: the core's compact prioritised replay
  (:class:`~mpg_agents.learning.replay.PrioritizedHeightmapReplayBuffer`) as SB3's ``DictReplayBuffer``.
"""

from mpg_agents.sb3.dqn import MPGDQN, sb3_settings
from mpg_agents.sb3.policy import MPGNetPolicy, MPGQNetwork
from mpg_agents.sb3.replay import SB3HeightmapReplayBuffer

__all__ = ["MPGDQN", "MPGNetPolicy", "MPGQNetwork", "SB3HeightmapReplayBuffer", "sb3_settings"]
