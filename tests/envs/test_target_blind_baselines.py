"""The scripted baselines that promise not to read how the target is named
(``reads_target_spec=False``: the oracle, random) play the same episode, action for action, on a
track and its visible and exemplar twins (the same scenes, the exemplar's recoloured); that
promise is what lets a table reuse their mask-track cells for the twins
(mpg_agents.evaluation.reused_cells, ``scenes_of``)."""

from __future__ import annotations

import gymnasium as gym
import pytest

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_envs.policies.registry import SCRIPTED_BASELINES, make_baseline

# (mask env id, a twin's id and keywords): the hard track's blocks, unseen shapes and camera images, each with
# the target named by its visible pixels and by an exemplar.
TWINS = {
    "blocks": ("MPG-OccludedHard-v0", "MPG-OccludedHardVisible-v0", {}),
    "unseen shapes": ("MPG-OccludedHardNovel-v0", "MPG-OccludedHardNovel-v0", {"target_spec": "visible"}),
    "camera": ("MPG-OccludedHardCamera-v0", "MPG-OccludedHardCamera-v0", {"target_spec": "visible"}),
    "blocks, exemplar": ("MPG-OccludedHard-v0", "MPG-OccludedHardExemplar-v0", {}),
    "unseen shapes, exemplar": ("MPG-OccludedHardNovel-v0", "MPG-OccludedHardNovelExemplar-v0", {}),
    "camera, exemplar": ("MPG-OccludedHardCamera-v0", "MPG-OccludedHardCameraExemplar-v0", {}),
}
BLIND = [name for name, baseline in SCRIPTED_BASELINES.items() if not baseline.reads_target_spec]
SEED = 500002  # a shipped scene of each track's test set; the oracle takes 3-5 motions on it


def _episode(env_id: str, kwargs: dict, policy_name: str, seed: int) -> list[tuple[int, float, bool, bool]]:
    """(action, reward, terminated, truncated) of each step of one seeded episode."""
    env = gym.make(env_id, **kwargs)
    try:
        policy = make_baseline(policy_name, env.unwrapped, seed)
        if hasattr(policy, "seed"):
            policy.seed(seed)
        obs, _ = env.reset(seed=seed)
        steps, done = [], False
        while not done:
            action = int(policy.act(obs))
            obs, reward, terminated, truncated, _ = env.step(action)
            steps.append((action, float(reward), bool(terminated), bool(truncated)))
            done = terminated or truncated
        return steps
    finally:
        env.close()


def test_the_oracle_and_random_promise_not_to_read_the_target_spec():
    assert set(BLIND) == {"oracle", "random"}
    assert SCRIPTED_BASELINES["matcher"].reads_target_spec  # the matcher acts on the exemplar


@pytest.mark.parametrize("policy_name", BLIND)
@pytest.mark.parametrize("track", list(TWINS))
def test_a_blind_baseline_plays_the_same_episode_on_a_twin(track, policy_name):
    mask_id, visible_id, keywords = TWINS[track]
    on_mask = _episode(mask_id, {}, policy_name, SEED)
    on_visible = _episode(visible_id, keywords, policy_name, SEED)
    assert on_mask == on_visible and on_mask
