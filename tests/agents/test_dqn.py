"""MPGDQN's training step (the shared td_step): double-DQN targets and surprise priorities."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch
from stable_baselines3.common.logger import configure

from mpg_agents import MPGDQN, MPGNetPolicy
from mpg_agents.learning.td_step import td_targets
from mpg_envs.grid.actions import encode_action

from .conftest import TINY
from .fake_env import FakeMPGEnv, random_scene


@pytest.fixture(scope="module")
def model() -> MPGDQN:
    env = FakeMPGEnv(("push", "grasp"))
    # No grasp symmetry: the expected surprise below is computed on the sampled transitions alone.
    model = MPGDQN(
        MPGNetPolicy, env, buffer_size=20, learning_starts=0, batch_size=2, seed=0, grasp_symmetry=False, policy_kwargs=dict(TINY)
    )
    model.set_logger(configure(None, []))
    rng = np.random.default_rng(0)
    obs = random_scene(rng, occluded=False)
    for t in range(6):
        nxt = random_scene(rng, occluded=False)
        rows, cols = np.nonzero(obs["mask"])
        action = encode_action(("push", "grasp"), "grasp" if t % 2 else "push", t, int(rows[0]), int(cols[0]))
        model.replay_buffer.add(
            {k: v[None] for k, v in obs.items()},
            {k: v[None] for k, v in nxt.items()},
            np.array([action]),
            np.array([t % 3 - 1.0]),
            np.array([t == 5]),
            [{}],
        )
        obs = nxt
    return model


def test_td_targets_are_double_dqn(model):
    data = model.replay_buffer.sample(3)
    q_net, q_target = model.q_net, model.q_net_target
    # Make the target net differ from the online net so the two roles are distinguishable.
    with torch.no_grad():
        for p in q_target.parameters():
            p.add_(0.01 * torch.randn_like(p))
    q_net.set_training_mode(False)
    q_target.set_training_mode(False)
    y = td_targets(q_net, q_target, data.next_observations, data.rewards, data.dones, 0.5)
    with torch.no_grad():
        enc = q_net.mpgnet.encode(data.next_observations)
        maps = q_net.mpgnet.maps_from(enc, q_net.action_primitives)
        best = q_net.masked_flat_q(maps, enc).argmax(dim=1)  # online net chooses
        evaluated = q_target(data.next_observations).gather(1, best[:, None])  # target net evaluates
    expected = data.rewards + (1 - data.dones) * 0.5 * evaluated
    assert torch.allclose(y, expected, atol=1e-4)
    model.q_net_target.load_state_dict(model.q_net.state_dict())


def test_train_step_sets_priorities_to_surprise(model):
    buffer = model.replay_buffer
    fixed = buffer.sample(2)
    untouched = np.setdiff1d(np.arange(buffer.size()), fixed.indices)
    before = buffer.priorities[:, 0].copy()
    # Expected surprise |Q(s, a) - y| computed the way train() does, on a copy of the policy.
    shadow = copy.deepcopy(model.policy)
    shadow.set_training_mode(True)
    y = td_targets(shadow.q_net, shadow.q_net_target, fixed.next_observations, fixed.rewards, fixed.dones, model.gamma)
    q = shadow.q_net.q_values_at(fixed.observations, fixed.actions)
    expected = (q - y).abs().detach().numpy().reshape(-1) + buffer.priority_eps
    original = buffer.sample
    buffer.sample = lambda *args, **kwargs: fixed
    try:
        model.train(gradient_steps=1, batch_size=2)
    finally:
        buffer.sample = original
    np.testing.assert_allclose(buffer.priorities[fixed.indices, 0], expected, rtol=1e-4)
    assert np.array_equal(buffer.priorities[untouched, 0], before[untouched])
