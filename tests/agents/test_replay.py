"""Compact prioritised replay: exact round trips, frame sharing, size, lazy allocation, priorities;
the core buffer without Stable-Baselines3, the SB3 adapter's buffer as SB3's."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.type_aliases import DictReplayBufferSamples

from mpg_agents.learning.replay import PrioritizedHeightmapReplayBuffer, ReplaySamples, sb3_dict_buffer_nbytes
from mpg_agents.sb3.replay import SB3HeightmapReplayBuffer
from mpg_envs.grid.actions import PixelActionSpace

from .fake_env import observation_space, random_scene


def make_buffer(size=50, n_envs=1, kind=PrioritizedHeightmapReplayBuffer, **kwargs) -> PrioritizedHeightmapReplayBuffer:
    return kind(
        size, observation_space(), PixelActionSpace(("grasp",)), device="cpu", n_envs=n_envs, **kwargs
    )


def batched(obs):
    return {k: v[None] for k, v in obs.items()}


def fill(buffer, rng, steps, episode=4):
    """Add an episode-structured stream; returns the list of (obs, next_obs, action, reward, done)."""
    added = []
    obs = random_scene(rng)
    for t in range(steps):
        nxt = obs if t % 7 == 3 else random_scene(rng)  # sometimes nothing changes
        # Arbitrary float32 bit patterns in depth, not just "nice" values.
        nxt = dict(
            nxt, depth=(nxt["depth"] + rng.uniform(0, 1e-3, nxt["depth"].shape).astype(np.float32) * (nxt["depth"] > 0))
        )
        action = np.array([rng.integers(0, 16 * 224 * 224)])
        reward = np.array([float(rng.random() < 0.3)], np.float32)
        done = np.array([(t + 1) % episode == 0])
        infos = [{"TimeLimit.truncated": False}]
        buffer.add(batched(obs), batched(nxt), action, reward, done, infos)
        added.append((obs, nxt, int(action[0]), float(reward[0]), bool(done[0])))
        obs = random_scene(rng) if done[0] else nxt
    return added


@pytest.mark.parametrize("kind", [PrioritizedHeightmapReplayBuffer, SB3HeightmapReplayBuffer])
def test_samples_round_trip_exactly(rng, kind):
    buffer = make_buffer(40, kind=kind)
    added = fill(buffer, rng, 30)
    samples = buffer.sample(16)
    if kind is SB3HeightmapReplayBuffer:
        assert isinstance(buffer, DictReplayBuffer)
        assert isinstance(samples, DictReplayBufferSamples)
    else:
        assert isinstance(samples, ReplaySamples)
    assert samples.actions.shape == (16, 1) and samples.rewards.shape == (16, 1) and samples.dones.shape == (16, 1)
    for i, idx in enumerate(samples.indices):
        obs, nxt, action, reward, done = added[idx]
        for key in obs:
            got = samples.observations[key][i].numpy()
            assert got.dtype == obs[key].dtype and np.array_equal(got, obs[key]), key
            assert np.array_equal(samples.next_observations[key][i].numpy(), nxt[key]), key
        # Depth bits are identical (no float16 quantisation).
        assert np.array_equal(samples.observations["depth"][i].numpy().view(np.uint32), obs["depth"].view(np.uint32))
        assert int(samples.actions[i, 0]) == action
        assert float(samples.rewards[i, 0]) == reward and float(samples.dones[i, 0]) == float(done)


def test_frames_are_shared_and_buffer_is_a_quarter_of_sb3(rng):
    buffer = make_buffer(64)
    fill(buffer, rng, 64)
    n = buffer.size()
    # Consecutive transitions within an episode share one frame object.
    assert buffer.next_obs_frames[0, 0] is buffer.obs_frames[1, 0]
    unique = {id(f) for f in np.concatenate([buffer.obs_frames[:n, 0], buffer.next_obs_frames[:n, 0]])}
    assert len(unique) < 1.4 * n  # ~1 frame per transition plus one per episode start
    sb3 = DictReplayBuffer(64, observation_space(), PixelActionSpace(("grasp",)), device="cpu")
    sb3_bytes = sb3_dict_buffer_nbytes(sb3)
    ours = buffer.nbytes()
    assert ours <= sb3_bytes / 4, (ours, sb3_bytes)
    assert buffer.bytes_per_transition() <= sb3_bytes / 64 / 4


def test_allocation_is_lazy():
    buffer = make_buffer(100_000)
    assert buffer.nbytes() < 10 * 100_000 * 8  # a few small arrays, nothing per observation
    with pytest.raises(ValueError, match="empty"):
        buffer.sample(1)


def test_non_binary_mask_values_are_kept(rng):
    buffer = make_buffer(4)
    obs = random_scene(rng)
    odd = dict(obs, mask=(obs["mask"] * 3).astype(np.uint8))  # not 0/1: stored without bit packing
    buffer.add(batched(odd), batched(obs), np.array([0]), np.array([0.0]), np.array([False]), [{}])
    s = buffer.sample(1)
    assert np.array_equal(s.observations["mask"][0].numpy(), odd["mask"])
    assert np.array_equal(s.next_observations["mask"][0].numpy(), obs["mask"])


def test_new_transitions_get_max_priority_and_surprise_drives_sampling():
    rng = np.random.default_rng(0)
    buffer = make_buffer(100, seed=123)
    fill(buffer, rng, 100)
    assert np.all(buffer.priorities[:100] == 1.0)
    surprising = np.arange(0, 100, 10)  # 10 transitions
    errors = np.full(100, 0.05)
    errors[surprising] = 5.0
    buffer.update_priorities(np.arange(100), errors)
    counts = np.zeros(100)
    for _ in range(50):
        np.add.at(counts, buffer.sample(20).indices, 1)
    share = counts[surprising].sum() / counts.sum()
    expected = 10 * 5.001 / (10 * 5.001 + 90 * 0.051)  # ~0.916
    assert abs(share - expected) < 0.05, share
    # A newly added transition starts at the largest priority seen.
    fill(buffer, rng, 1)
    assert buffer.priorities[0, 0] == pytest.approx(5.001)
    with pytest.raises(ValueError, match="indices but"):
        buffer.update_priorities(np.arange(3), np.zeros(2))


def test_multiple_envs(rng):
    buffer = make_buffer(20, n_envs=2)
    scenes = [random_scene(rng) for _ in range(4)]
    for t in range(3):
        obs = {k: np.stack([scenes[t][k], scenes[t + 1][k]]) for k in scenes[0]}
        nxt = {k: np.stack([scenes[t + 1][k], scenes[t][k]]) for k in scenes[0]}
        buffer.add(obs, nxt, np.array([[1], [2]]), np.array([0.0, 1.0]), np.array([False, False]), [{}, {}])
    s = buffer.sample(8)
    for i, flat in enumerate(s.indices):
        pos, env = divmod(int(flat), 2)
        assert int(s.actions[i, 0]) == env + 1
        expected = scenes[pos + env]["color"]
        assert np.array_equal(s.observations["color"][i].numpy(), expected)
    assert isinstance(s.observations["color"], torch.Tensor)


def test_the_core_buffer_and_the_learner_import_no_stable_baselines3():
    import subprocess
    import sys

    code = (
        "import sys, mpg_agents.learning.replay, mpg_agents.learning.learner; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'stable_baselines3'))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout
