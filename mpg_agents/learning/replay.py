"""Compact, surprise-prioritised replay of heightmap transitions on SB3's buffer API.

Storage (exact, lossless): each observation is kept once as a :class:`Frame` of compressed
planes and shared by reference between consecutive transitions (the ``next_obs`` of step t
is the ``obs`` of step t + 1, and a no-change step reuses its own frame). Per key:

- 0/1 uint8 planes (the mask) are bit-packed, then deflated;
- other uint8 planes (colour) are deflated;
- wider dtypes (float32 depth) are byte-shuffled (all first bytes, then all second bytes, ...)
  and deflated, so the slowly varying exponent bytes compress well; decoding restores the
  exact bits, so depth round-trips bit for bit (no float16 quantisation);
- small planes (``occluded``) are stored raw.

Nothing is preallocated per observation: frames exist only for stored transitions, and a
frame is freed when the last transition referencing it is overwritten.

Sampling is proportional to ``priority ** alpha`` with ``priority = |Q - y| + eps`` (surprise);
new transitions get the largest priority seen so far so each is replayed at least once
early. :meth:`PrioritizedHeightmapReplayBuffer.update_priorities` takes the indices the
samples carry.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.buffers import BaseBuffer, DictReplayBuffer
from stable_baselines3.common.type_aliases import DictReplayBufferSamples
from stable_baselines3.common.vec_env import VecNormalize

_RAW_LIMIT = 64  # planes up to this many bytes are cheaper raw than deflated


@dataclass(frozen=True)
class PlaneCodec:
    """How one observation key is stored: dtype, shape and encoding ("bits", "deflate", "shuffle", "raw")."""

    dtype: np.dtype
    shape: tuple[int, ...]
    binary_hint: bool

    def encode(self, value: np.ndarray, level: int) -> tuple[str, bytes]:
        arr = np.ascontiguousarray(value, dtype=self.dtype).reshape(self.shape)
        if arr.nbytes <= _RAW_LIMIT:
            return "raw", arr.tobytes()
        if self.binary_hint and arr.dtype == np.uint8 and int(arr.max(initial=0)) <= 1:
            return "bits", zlib.compress(np.packbits(arr.reshape(-1)).tobytes(), level)
        if arr.dtype.itemsize == 1:
            return "deflate", zlib.compress(arr.tobytes(), level)
        shuffled = arr.reshape(-1).view(np.uint8).reshape(-1, arr.dtype.itemsize).T
        return "shuffle", zlib.compress(np.ascontiguousarray(shuffled).tobytes(), level)

    def decode(self, kind: str, blob: bytes) -> np.ndarray:
        count = int(np.prod(self.shape))
        if kind == "raw":
            return np.frombuffer(blob, dtype=self.dtype).reshape(self.shape).copy()
        data = zlib.decompress(blob)
        if kind == "bits":
            return np.unpackbits(np.frombuffer(data, np.uint8), count=count).astype(self.dtype).reshape(self.shape)
        if kind == "deflate":
            return np.frombuffer(data, dtype=self.dtype).reshape(self.shape).copy()
        if kind == "shuffle":
            planes = np.frombuffer(data, np.uint8).reshape(self.dtype.itemsize, count)
            return np.ascontiguousarray(planes.T).view(self.dtype).reshape(self.shape)
        raise ValueError(f"unknown plane encoding {kind!r}")


class Frame:
    """One stored observation: an encoded blob per key."""

    __slots__ = ("planes", "nbytes")

    def __init__(self, planes: dict[str, tuple[str, bytes]]) -> None:
        self.planes = planes
        self.nbytes = sum(len(blob) for _, blob in planes.values())


class PrioritizedDictReplayBufferSamples(DictReplayBufferSamples):
    """SB3's ``DictReplayBufferSamples`` plus the sampled buffer ``indices`` (for priority updates)."""

    indices: np.ndarray

    def __new__(cls, *args: Any, indices: np.ndarray, **kwargs: Any) -> "PrioritizedDictReplayBufferSamples":
        self = super().__new__(cls, *args, **kwargs)
        self.indices = indices
        return self


class PrioritizedHeightmapReplayBuffer(DictReplayBuffer):
    """SB3 ``DictReplayBuffer`` drop-in: compact lossless heightmap storage + surprise priorities.

    Args:
        buffer_size: transitions kept (per env: ``buffer_size // n_envs``).
        observation_space: as in SB3.
        action_space: as in SB3.
        device: as in SB3.
        n_envs: as in SB3.
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
        BaseBuffer.__init__(self, buffer_size, observation_space, action_space, device, n_envs=n_envs)
        self.buffer_size = max(buffer_size // n_envs, 1)
        self.optimize_memory_usage = False
        self.handle_timeout_termination = handle_timeout_termination
        self.alpha = float(alpha)
        self.priority_eps = float(priority_eps)
        self.compression_level = int(compression_level)
        self._rng = np.random.default_rng(seed) if seed is not None else None
        self.codecs = {
            key: PlaneCodec(np.dtype(sub.dtype), tuple(self.obs_shape[key]), _is_binary(sub))
            for key, sub in observation_space.spaces.items()
        }
        shape = (self.buffer_size, self.n_envs)
        self.obs_frames = np.empty(shape, dtype=object)
        self.next_obs_frames = np.empty(shape, dtype=object)
        self.actions = np.zeros((*shape, self.action_dim), dtype=self._maybe_cast_dtype(action_space.dtype))
        self.rewards = np.zeros(shape, dtype=np.float32)
        self.dones = np.zeros(shape, dtype=np.float32)
        self.timeouts = np.zeros(shape, dtype=np.float32)
        self.priorities = np.zeros(shape, dtype=np.float64)
        self.max_priority = 1.0
        # Last stored next-observation per env, raw, to share it with the following transition.
        self._last_next: list[tuple[dict[str, np.ndarray], Frame] | None] = [None] * self.n_envs

    # The parent's dict-of-arrays attributes do not exist here; decoded views on demand.
    @property
    def observations(self) -> dict[str, np.ndarray]:  # type: ignore[override]
        """Decoded stored observations ``{key: (size, n_envs, ...)}`` (slow; for inspection)."""
        return self._decode_all(self.obs_frames)

    @property
    def next_observations(self) -> dict[str, np.ndarray]:  # type: ignore[override]
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
    def add(  # type: ignore[override]
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

    def reset(self) -> None:
        super().reset()
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
    def rng_state(self) -> dict | None:
        """The sampling generator's state (``None`` when the buffer was built without a seed)."""
        return self._rng.bit_generator.state if self._rng is not None else None

    @rng_state.setter
    def rng_state(self, state: dict | None) -> None:
        if (state is None) != (self._rng is None):
            raise ValueError("a seeded buffer needs a generator state and an unseeded one none")
        if self._rng is not None:
            self._rng.bit_generator.state = state

    def sampling_probabilities(self) -> np.ndarray:
        """Probability of each stored transition, flat index ``pos * n_envs + env``."""
        p = self.priorities[: self.size()].reshape(-1) ** self.alpha
        return p / p.sum()

    def sample(self, batch_size: int, env: VecNormalize | None = None) -> PrioritizedDictReplayBufferSamples:  # type: ignore[override]
        """Draw ``batch_size`` transitions with probability proportional to ``priority ** alpha``."""
        if self.size() == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        cumulative = np.cumsum(self.priorities[: self.size()].reshape(-1) ** self.alpha)
        draws = (self._rng.random(batch_size) if self._rng is not None else np.random.random(batch_size)) * cumulative[
            -1
        ]
        flat = np.minimum(np.searchsorted(cumulative, draws, side="right"), cumulative.size - 1)
        return self._get_flat_samples(flat, env)

    def _get_samples(  # type: ignore[override]
        self, batch_inds: np.ndarray, env: VecNormalize | None = None
    ) -> PrioritizedDictReplayBufferSamples:
        # SB3's uniform path (BaseBuffer.sample) draws positions and picks envs at random.
        envs = np.random.randint(0, high=self.n_envs, size=(len(batch_inds),))
        return self._get_flat_samples(np.asarray(batch_inds) * self.n_envs + envs, env)

    def _get_flat_samples(self, flat: np.ndarray, env: VecNormalize | None) -> PrioritizedDictReplayBufferSamples:
        pos, envs = np.divmod(flat, self.n_envs)
        obs = [self.decode(self.obs_frames[p, e]) for p, e in zip(pos, envs, strict=True)]
        nxt = [self.decode(self.next_obs_frames[p, e]) for p, e in zip(pos, envs, strict=True)]
        obs_ = self._normalize_obs({k: np.stack([o[k] for o in obs]) for k in self.codecs}, env)
        nxt_ = self._normalize_obs({k: np.stack([o[k] for o in nxt]) for k in self.codecs}, env)
        assert isinstance(obs_, dict) and isinstance(nxt_, dict)
        dones = self.dones[pos, envs] * (1 - self.timeouts[pos, envs])
        return PrioritizedDictReplayBufferSamples(
            observations={k: self.to_torch(v) for k, v in obs_.items()},
            actions=self.to_torch(self.actions[pos, envs]),
            next_observations={k: self.to_torch(v) for k, v in nxt_.items()},
            dones=self.to_torch(dones).reshape(-1, 1),
            rewards=self.to_torch(self._normalize_reward(self.rewards[pos, envs].reshape(-1, 1), env)),
            indices=flat,
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


def sb3_dict_buffer_nbytes(buffer: DictReplayBuffer) -> int:
    """Bytes SB3's own ``DictReplayBuffer`` holds (its preallocated arrays), for comparisons."""
    arrays = (*buffer.observations.values(), *buffer.next_observations.values(), buffer.actions, buffer.rewards, buffer.dones, buffer.timeouts)
    return sum(a.nbytes for a in arrays)


def _is_binary(space: spaces.Space) -> bool:
    """A uint8 Box with bounds 0..1 (the mask) or a MultiBinary space."""
    if isinstance(space, spaces.MultiBinary):
        return True
    return (
        isinstance(space, spaces.Box)
        and np.dtype(space.dtype) == np.uint8
        and bool(np.all(space.low == 0))
        and bool(np.all(space.high == 1))
    )
