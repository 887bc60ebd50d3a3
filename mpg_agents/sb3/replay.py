"""The SB3 adapter's replay buffer: the core's compact prioritised buffer as SB3's ``DictReplayBuffer``.

:class:`SB3HeightmapReplayBuffer` stores and samples as
:class:`~mpg_agents.learning.replay.PrioritizedHeightmapReplayBuffer` does; it adds only what
SB3 asks of a buffer: being a ``DictReplayBuffer``, SB3's ``VecNormalize`` on sampled batches,
and SB3's sample type (with the sampled ``indices`` the priorities are written back to).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.type_aliases import DictReplayBufferSamples
from stable_baselines3.common.vec_env import VecNormalize

from mpg_agents.learning.replay import PrioritizedHeightmapReplayBuffer


class PrioritizedDictReplayBufferSamples(DictReplayBufferSamples):
    """SB3's ``DictReplayBufferSamples`` plus the sampled buffer ``indices`` (for priority updates)."""

    indices: np.ndarray

    def __new__(cls, *args: Any, indices: np.ndarray, **kwargs: Any) -> PrioritizedDictReplayBufferSamples:
        self = super().__new__(cls, *args, **kwargs)
        self.indices = indices
        return self


# SB3's buffers declare dict-of-array storage and their own signatures; this one keeps compact
# frames and answers the calls SB3 makes (mypy cannot see the two as one class).
class SB3HeightmapReplayBuffer(PrioritizedHeightmapReplayBuffer, DictReplayBuffer):  # type: ignore[misc, override]
    """:class:`~mpg_agents.learning.replay.PrioritizedHeightmapReplayBuffer` that is SB3's
    ``DictReplayBuffer`` (``MPGDQN``'s default ``replay_buffer_class``); same arguments.

    SB3's ``DictReplayBuffer.__init__`` is not run: it would preallocate every observation.
    """

    def batch(  # type: ignore[override]
        self,
        obs: dict[str, np.ndarray],
        actions: np.ndarray,
        next_obs: dict[str, np.ndarray],
        dones: np.ndarray,
        rewards: np.ndarray,
        indices: np.ndarray,
        env: VecNormalize | None = None,
    ) -> PrioritizedDictReplayBufferSamples:
        """SB3's sample type, with ``env``'s observation and reward normalisation applied."""
        obs_ = self._normalize_obs(obs, env)
        nxt_ = self._normalize_obs(next_obs, env)
        assert isinstance(obs_, dict) and isinstance(nxt_, dict)
        return PrioritizedDictReplayBufferSamples(
            observations={k: self.to_torch(v) for k, v in obs_.items()},
            actions=self.to_torch(actions),
            next_observations={k: self.to_torch(v) for k, v in nxt_.items()},
            dones=self.to_torch(dones),
            rewards=self.to_torch(self._normalize_reward(rewards, env)),
            indices=indices,
        )

    def _get_samples(  # type: ignore[override]
        self, batch_inds: np.ndarray, env: VecNormalize | None = None
    ) -> PrioritizedDictReplayBufferSamples:
        # SB3's uniform path (BaseBuffer.sample) draws positions and picks envs at random.
        envs = np.random.randint(0, high=self.n_envs, size=(len(batch_inds),))
        return self.samples_at(np.asarray(batch_inds) * self.n_envs + envs, env)  # type: ignore[return-value]
