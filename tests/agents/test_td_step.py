"""The one gradient step (mpg_agents.learning.td_step) that MPGDQN and the learner share."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch

from mpg_agents.learning.replay import PrioritizedHeightmapReplayBuffer
from mpg_agents.learning.td_step import TDStepConfig, td_step
from mpg_envs.grid.actions import PixelActionSpace, encode_action

from .fake_env import observation_space, random_scene

PRIMS = ("push", "grasp")


@pytest.fixture(scope="module")
def setup(build_policy):
    policy = build_policy(observation_space(), PixelActionSpace(PRIMS))
    replay = PrioritizedHeightmapReplayBuffer(8, observation_space(), PixelActionSpace(PRIMS), device="cpu", seed=0)
    rng = np.random.default_rng(3)
    obs = random_scene(rng, occluded=False)
    for t, (prim, rot) in enumerate([("push", 2), ("grasp", 3), ("grasp", 12)]):
        nxt = random_scene(rng, occluded=False)
        rows, cols = np.nonzero(obs["mask"])
        action = encode_action(PRIMS, prim, rot, int(rows[0]), int(cols[0]))
        replay.add({k: v[None] for k, v in obs.items()}, {k: v[None] for k, v in nxt.items()},
                   np.array([[action]]), np.array([1.0 - t], np.float32), np.array([0.0], np.float32), [{}])
        obs = nxt
    return policy, replay


def test_frozen_primitives_do_not_learn_and_get_zero_surprise(setup):
    policy, replay = setup
    policy = copy.deepcopy(policy)
    batch = replay.sample(3)
    prims = [PRIMS[int(a) // (16 * 224 * 224)] for a in batch.actions.reshape(-1)]
    push_before = [p.detach().clone() for p in policy.q_net.mpgnet.branches["push"].parameters()]
    result = td_step(policy.q_net, policy.q_net_target, policy.optimizer, batch, TDStepConfig(), active=("grasp",))
    for prim, s in zip(prims, result.surprise):
        assert (s == 0) == (prim == "push")
    # The push branch had no gradient: Adam leaves it untouched (weight decay acts through the gradient).
    for a, b in zip(push_before, policy.q_net.mpgnet.branches["push"].parameters(), strict=True):
        assert torch.equal(a, b)
    none = td_step(policy.q_net, policy.q_net_target, policy.optimizer, batch, TDStepConfig(), active=("move",))
    assert not none.trained and not none.surprise.any()


def test_grasp_symmetry_trains_the_turned_rotation(setup, monkeypatch):
    policy, replay = setup
    policy = copy.deepcopy(policy)
    batch = replay.sample(3)
    seen = []
    original = policy.q_net.q_values_at
    monkeypatch.setattr(policy.q_net, "q_values_at", lambda obs, acts: (seen.append(acts.clone()), original(obs, acts))[1])
    td_step(policy.q_net, policy.q_net_target, policy.optimizer, batch, TDStepConfig(grasp_symmetry=True))
    acts = seen[-1]
    per_rot = 224 * 224
    grasps = [int(a) for a in batch.actions.reshape(-1) if int(a) // (16 * per_rot) == 1]
    turned = [a + (8 if (a // per_rot) % 16 < 8 else -8) * per_rot for a in grasps]
    assert acts[: len(batch.actions)].tolist() == batch.actions.reshape(-1).tolist()
    assert acts[len(batch.actions):].tolist() == turned


def test_gradient_clipping_bounds_the_step(setup):
    policy, replay = setup
    batch = replay.sample(3)
    clipped = copy.deepcopy(policy)
    # Plain SGD makes the update proportional to the (clipped) gradient.
    sgd = torch.optim.SGD(clipped.q_net.parameters(), lr=1.0)
    before = [p.detach().clone() for p in clipped.q_net.parameters()]
    td_step(clipped.q_net, clipped.q_net_target, sgd, batch, TDStepConfig(max_grad_norm=1e-3))
    norm = torch.sqrt(sum(((a - b.detach()) ** 2).sum() for a, b in zip(before, clipped.q_net.parameters(), strict=True)))
    assert float(norm) <= 1e-3 * 1.01
    with pytest.raises(ValueError, match="max_grad_norm"):
        TDStepConfig(max_grad_norm=0.0)


def test_priorities_written_when_a_buffer_is_given(setup):
    policy, replay = setup
    policy = copy.deepcopy(policy)
    batch = replay.sample(2)
    result = td_step(policy.q_net, policy.q_net_target, policy.optimizer, batch, TDStepConfig(grasp_symmetry=False), replay=replay)
    np.testing.assert_allclose(replay.priorities[batch.indices, 0], result.surprise + replay.priority_eps, rtol=1e-6)


def test_target_bounds_clamp_the_td_targets(setup):
    from mpg_agents.learning.td_step import td_targets

    policy, replay = setup
    batch = replay.sample(3)
    rewards = torch.tensor([5.0, -3.0, 0.5])  # outside, outside, inside [-1, 2]
    free = td_targets(policy.q_net, policy.q_net_target, batch.next_observations, rewards, torch.ones(3), 0.5)
    clamped = td_targets(policy.q_net, policy.q_net_target, batch.next_observations, rewards, torch.ones(3), 0.5, (-1.0, 2.0))
    assert free.reshape(-1).tolist() == [5.0, -3.0, 0.5]  # done: the target is the reward
    assert clamped.reshape(-1).tolist() == [2.0, -1.0, 0.5]
    assert TDStepConfig(target_bounds=[-1, 2]).target_bounds == (-1.0, 2.0)
    with pytest.raises(ValueError, match="target_bounds"):
        TDStepConfig(target_bounds=(2.0, -1.0))


def test_terminal_samples_take_the_reward_and_live_ones_their_own_bootstrap(setup):
    from mpg_agents.learning.td_step import td_targets

    policy, replay = setup
    batch = replay.sample(3)
    rewards = torch.tensor([0.25, 1.0, -0.5])
    dones = torch.tensor([0.0, 1.0, 0.0])  # the terminal one skips the next-state passes
    mixed = td_targets(policy.q_net, policy.q_net_target, batch.next_observations, rewards, dones, 0.5)
    assert mixed[1, 0].item() == 1.0
    for i in (0, 2):  # a live sample's target does not depend on what else is in the batch
        alone = td_targets(
            policy.q_net, policy.q_net_target, {k: v[i : i + 1] for k, v in batch.next_observations.items()},
            rewards[i : i + 1], dones[i : i + 1], 0.5,
        )
        assert torch.allclose(mixed[i], alone[0], atol=1e-5)
