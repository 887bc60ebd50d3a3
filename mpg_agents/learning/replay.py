"""Compact, surprise-prioritised replay of heightmap transitions (SB3's buffer API, without SB3).

Storage (exact, lossless): each observation is kept once as a compressed
:class:`~mpg_agents.learning.replay_codec.Frame` (:mod:`mpg_agents.learning.replay_codec`: the mask
bit-packed, colour deflated, depth byte-shuffled and deflated, bit for bit) and shared by
reference between consecutive transitions (the ``next_obs`` of step t is the ``obs`` of step
t + 1, and a no-change step reuses its own frame).

Nothing is preallocated per observation: frames exist only for stored transitions, and a
frame is freed when the last transition referencing it is overwritten.

Sampling is proportional to ``priority ** alpha`` with ``priority = |Q - y| + eps`` (surprise);
new transitions get the largest priority seen so far so each is replayed at least once
early. :meth:`PrioritizedHeightmapReplayBuffer.update_priorities` takes the indices the
samples carry.

The buffer speaks SB3's buffer API (``add``, ``sample``, ``size``, ``reset``, ``pos``, ``full``)
but imports no Stable-Baselines3: ``mpg-train`` runs without it. The SB3 adapter's buffer
(:class:`mpg_agents.sb3.replay.SB3HeightmapReplayBuffer`) is a thin subclass that is also SB3's
``DictReplayBuffer`` and returns SB3's sample type.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch
from gymnasium import spaces
from torch import Tensor

from mpg_agents.learning.replay_codec import Frame, PlaneCodec, is_binary_space


class ReplaySamples(NamedTuple):
    """A sampled batch (the fields of SB3's ``DictReplayBufferSamples``, plus the buffer
    ``indices`` the priorities are written back to)."""

    observations: dict[str, Tensor]
    actions: Tensor  # (B, action_dim)
    next_observations: dict[str, Tensor]
    dones: Tensor  # (B, 1): terminal, not truncated
    rewards: Tensor  # (B, 1)
    indices: np.ndarray  # (B,) flat buffer index ``pos * n_envs + env``
    discounts: Tensor | None = None  # per-sample discounts (none here: the step's gamma)


class PrioritizedHeightmapReplayBuffer:
    """Compact lossless heightmap storage + surprise priorities, on SB3's buffer API.

    Args:
        buffer_size: transitions kept (per env: ``buffer_size // n_envs``).
        observation_space: as in SB3.
        action_space: as in SB3.
        device: where sampled batches go (``"auto"``: CUDA when available); storage stays on the host.
        n_envs: parallel envs whose steps :meth:`add` takes at once.
        optimize_memory_usage: accepted for SB3's signature; frame sharing already stores
            each observation once, so it changes nothing.
        handle_timeout_termination: as in SB3 (truncations do not end the bootstrap).
        alpha: priority exponent (1 = proportional to surprise, 0 = uniform).
        priority_eps: added to ``|td error|`` so no transition becomes unreachable.
        compression_level: zlib level (1 = fast; heightmaps compress well already).
        seed: seeds a private generator; ``None`` uses ``np.random`` (which SB3 seeds).
    """

    def __init__(
        self,
        buffer_size: int,
        observation_space: spaces.Dict,
        action_space: spaces.Space,
        device: torch.device | str = "auto",
        n_envs: int = 1,
        optimize_memory_usage: bool = False,
        handle_timeout_termination: bool = True,
        alpha: float = 1.0,
        priority_eps: float = 1e-3,
        compression_level: int = 1,
        seed: int | None = None,
    ) -> None:
        if not isinstance(observation_space, spaces.Dict):
            raise TypeError(f"PrioritizedHeightmapReplayBuffer needs a Dict observation space, got {observation_space}")
        if alpha < 0 or priority_eps <= 0:
            raise ValueError(f"need alpha >= 0 and priority_eps > 0, got alpha={alpha}, priority_eps={priority_eps}")
        self.observation_space = observation_space
        self.action_space = action_space
        self.obs_shape = {key: tuple(sub.shape or ()) for key, sub in observation_space.spaces.items()}
        self.action_dim = 1 if isinstance(action_space, spaces.Discrete) else int(np.prod(action_space.shape or ()))
        self.device = _device(device)
        self.n_envs = int(n_envs)
        self.buffer_size = max(buffer_size // n_envs, 1)
        self.pos = 0
        self.full = False
        self.optimize_memory_usage = False
        self.handle_timeout_termination = handle_timeout_termination
        self.alpha = float(alpha)
        self.priority_eps = float(priority_eps)
        self.compression_level = int(compression_level)
        self._rng = np.random.default_rng(seed) if seed is not None else None
        self.codecs = {
            key: PlaneCodec(np.dtype(sub.dtype), tuple(self.obs_shape[key]), is_binary_space(sub))
            for key, sub in observation_space.spaces.items()
        }
        shape = (self.buffer_size, self.n_envs)
        self.obs_frames = np.empty(shape, dtype=object)
        self.next_obs_frames = np.empty(shape, dtype=object)
        # float64 actions are kept as float32, as SB3 does
        action_dtype = np.float32 if np.dtype(action_space.dtype) == np.float64 else action_space.dtype
        self.actions = np.zeros((*shape, self.action_dim), dtype=action_dtype)
        self.rewards = np.zeros(shape, dtype=np.float32)
        self.dones = np.zeros(shape, dtype=np.float32)
        self.timeouts = np.zeros(shape, dtype=np.float32)
        self.priorities = np.zeros(shape, dtype=np.float64)
        self.max_priority = 1.0
        # Last stored next-observation per env, raw, to share it with the following transition.
        self._last_next: list[tuple[dict[str, np.ndarray], Frame] | None] = [None] * self.n_envs

    # The parent's dict-of-arrays attributes do not exist here; decoded views on demand.
    @property
    def observations(self) -> dict[str, np.ndarray]:
        """Decoded stored observations ``{key: (size, n_envs, ...)}`` (slow; for inspection)."""
        return self._decode_all(self.obs_frames)

    @property
    def next_observations(self) -> dict[str, np.ndarray]:
        """Decoded stored next observations (slow; for inspection)."""
        return self._decode_all(self.next_obs_frames)

    def _decode_all(self, frames: np.ndarray) -> dict[str, np.ndarray]:
        n = self.size()
        rows = [[self.decode(frames[i, e]) for e in range(self.n_envs)] for i in range(n)]
        return {
            key: np.array([[r[e][key] for e in range(self.n_envs)] for r in rows]).reshape(n, self.n_envs, *c.shape)
            for key, c in self.codecs.items()
        }

    # -------------------------------------------------------------- codec
    def encode(self, obs: dict[str, np.ndarray]) -> Frame:
        """Compress one (unbatched) observation."""
        return Frame({key: codec.encode(obs[key], self.compression_level) for key, codec in self.codecs.items()})

    def decode(self, frame: Frame) -> dict[str, np.ndarray]:
        """Exact inverse of :meth:`encode`."""
        return {key: codec.decode(*frame.planes[key]) for key, codec in self.codecs.items()}

    def _single(self, obs: dict[str, np.ndarray], env: int) -> dict[str, np.ndarray]:
        out = {}
        for key, codec in self.codecs.items():
            if key not in obs:
                raise KeyError(f"observation lacks key {key!r}; the buffer stores {sorted(self.codecs)}")
            value = np.asarray(obs[key]).reshape((self.n_envs, *codec.shape))[env]
            out[key] = value
        return out

    @staticmethod
    def _same(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> bool:
        return all(np.array_equal(a[k], b[k]) for k in a)

    # ---------------------------------------------------------------- API
    def add(
        self,
        obs: dict[str, np.ndarray],
        next_obs: dict[str, np.ndarray],
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        """Store one step of ``n_envs`` transitions (SB3 signature)."""
        for env in range(self.n_envs):
            current = self._single(obs, env)
            last = self._last_next[env]
            if last is not None and self._same(current, last[0]):
                frame = last[1]
            else:
                frame = self.encode(current)
            nxt = self._single(next_obs, env)
            next_frame = frame if self._same(nxt, current) else self.encode(nxt)
            self.obs_frames[self.pos, env] = frame
            self.next_obs_frames[self.pos, env] = next_frame
            self._last_next[env] = ({k: np.array(v, copy=True) for k, v in nxt.items()}, next_frame)
        self.actions[self.pos] = np.asarray(action).reshape((self.n_envs, self.action_dim))
        self.rewards[self.pos] = np.asarray(reward).reshape(self.n_envs)
        self.dones[self.pos] = np.asarray(done).reshape(self.n_envs)
        if self.handle_timeout_termination:
            self.timeouts[self.pos] = np.array([info.get("TimeLimit.truncated", False) for info in infos])
        self.priorities[self.pos] = self.max_priority
        self.pos += 1
        if self.pos == self.buffer_size:
            self.full = True
            self.pos = 0

    def size(self) -> int:
        """Stored steps (per env)."""
        return self.buffer_size if self.full else self.pos

    def to_torch(self, array: np.ndarray, copy: bool = True) -> Tensor:
        """``array`` as a tensor on the buffer's device."""
        return torch.tensor(array, device=self.device) if copy else torch.as_tensor(array, device=self.device)

    def reset(self) -> None:
        """Forget every stored transition."""
        self.pos = 0
        self.full = False
        self.obs_frames[:] = None
        self.next_obs_frames[:] = None
        self.priorities[:] = 0.0
        self.max_priority = 1.0
        self._last_next = [None] * self.n_envs

    def forget_last_frames(self) -> None:
        """Share nothing with the last stored frame: the next :meth:`add` starts a fresh episode
        (after :func:`mpg_agents.learning.run_state.load_replay`, whose frames were not added here)."""
        self._last_next = [None] * self.n_envs

    @property
    def rng_state(self) -> dict[str, Any] | None:
        """The sampling generator's state (``None`` when the buffer was built without a seed)."""
        return dict(self._rng.bit_generator.state) if self._rng is not None else None

    @rng_state.setter
    def rng_state(self, state: dict[str, Any] | None) -> None:
        if (state is None) != (self._rng is None):
            raise ValueError("a seeded buffer needs a generator state and an unseeded one none")
        if self._rng is not None and state is not None:
            self._rng.bit_generator.state = state

    def sampling_probabilities(self) -> np.ndarray:
        """Probability of each stored transition, flat index ``pos * n_envs + env``."""
        p = self.priorities[: self.size()].reshape(-1) ** self.alpha
        return p / p.sum()

    def sample(self, batch_size: int, env: Any = None) -> ReplaySamples:
        """Draw ``batch_size`` transitions with probability proportional to ``priority ** alpha``
        (``env``: SB3's observation normaliser, which only the SB3 adapter's buffer applies)."""
        if self.size() == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        cumulative = np.cumsum(self.priorities[: self.size()].reshape(-1) ** self.alpha)
        draws = (self._rng.random(batch_size) if self._rng is not None else np.random.random(batch_size)) * cumulative[-1]
        flat = np.minimum(np.searchsorted(cumulative, draws, side="right"), cumulative.size - 1)
        return self.samples_at(flat, env)

    def samples_at(self, flat: np.ndarray, env: Any = None) -> ReplaySamples:
        """The stored transitions at flat indices ``flat`` (``pos * n_envs + env``) as a batch."""
        pos, envs = np.divmod(np.asarray(flat), self.n_envs)
        obs = [self.decode(self.obs_frames[p, e]) for p, e in zip(pos, envs, strict=True)]
        nxt = [self.decode(self.next_obs_frames[p, e]) for p, e in zip(pos, envs, strict=True)]
        dones = self.dones[pos, envs] * (1 - self.timeouts[pos, envs])
        return self.batch(
            {k: np.stack([o[k] for o in obs]) for k in self.codecs},
            self.actions[pos, envs],
            {k: np.stack([o[k] for o in nxt]) for k in self.codecs},
            dones.reshape(-1, 1),
            self.rewards[pos, envs].reshape(-1, 1),
            np.asarray(flat),
            env,
        )

    def batch(
        self,
        obs: dict[str, np.ndarray],
        actions: np.ndarray,
        next_obs: dict[str, np.ndarray],
        dones: np.ndarray,
        rewards: np.ndarray,
        indices: np.ndarray,
        env: Any = None,
    ) -> ReplaySamples:
        """Decoded arrays as the sample type, on the buffer's device (the SB3 adapter returns SB3's type)."""
        if env is not None:
            raise ValueError("this buffer applies no observation normaliser (env); use the SB3 adapter's buffer")
        return ReplaySamples(
            observations={k: self.to_torch(v) for k, v in obs.items()},
            actions=self.to_torch(actions),
            next_observations={k: self.to_torch(v) for k, v in next_obs.items()},
            dones=self.to_torch(dones),
            rewards=self.to_torch(rewards),
            indices=indices,
        )

    def update_priorities(self, indices: np.ndarray, td_errors: np.ndarray | torch.Tensor) -> None:
        """Set the priority of sampled transitions to ``|td error| + eps`` (their surprise)."""
        if isinstance(td_errors, torch.Tensor):
            td_errors = td_errors.detach().cpu().numpy()
        errors = np.abs(np.asarray(td_errors, dtype=np.float64).reshape(-1))
        indices = np.asarray(indices).reshape(-1)
        if errors.shape != indices.shape:
            raise ValueError(f"got {indices.size} indices but {errors.size} td errors")
        if not np.all(np.isfinite(errors)):
            raise ValueError("td errors must be finite")
        if indices.size and (indices.min() < 0 or indices.max() >= self.size() * self.n_envs):
            raise ValueError(f"indices must lie in 0..{self.size() * self.n_envs - 1}")
        priorities = errors + self.priority_eps
        pos, envs = np.divmod(indices, self.n_envs)
        self.priorities[pos, envs] = priorities
        if priorities.size:
            self.max_priority = max(self.max_priority, float(priorities.max()))

    # ------------------------------------------------------------ memory
    def _frame_bytes(self) -> int:
        """Bytes of the distinct compressed frames the stored transitions reference."""
        seen: dict[int, int] = {}
        n = self.size()
        for frames in (self.obs_frames[:n], self.next_obs_frames[:n]):
            for frame in frames.reshape(-1):
                if frame is not None:
                    seen[id(frame)] = frame.nbytes
        return sum(seen.values())

    def _slot_arrays(self) -> tuple[np.ndarray, ...]:
        return (self.actions, self.rewards, self.dones, self.timeouts, self.priorities, self.obs_frames, self.next_obs_frames)

    def nbytes(self) -> int:
        """Bytes held: unique compressed frames plus the per-transition arrays."""
        return self._frame_bytes() + sum(a.nbytes for a in self._slot_arrays())

    def bytes_per_transition(self) -> float:
        """:meth:`nbytes` divided by the stored transitions (the per-slot arrays are for the capacity)."""
        n = self.size() * self.n_envs
        if n == 0:
            raise ValueError("the buffer is empty")
        per_slot = sum(a.itemsize * int(np.prod(a.shape[2:])) for a in self._slot_arrays())
        return self._frame_bytes() / n + per_slot


def sb3_dict_buffer_nbytes(buffer: Any) -> int:
    """Bytes SB3's own ``DictReplayBuffer`` holds (its preallocated arrays), for comparisons."""
    arrays = (
        *buffer.observations.values(),
        *buffer.next_observations.values(),
        buffer.actions,
        buffer.rewards,
        buffer.dones,
        buffer.timeouts,
    )
    return sum(a.nbytes for a in arrays)


def _device(device: torch.device | str) -> torch.device:
    """``"auto"``: CUDA when available, else the CPU (SB3's meaning)."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(device)
