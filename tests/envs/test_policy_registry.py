"""The scripted baselines' one registry (mpg_envs.policies.registry) and the pixel heuristic's
grasp (mpg_envs.policies.pixel_heuristic), checked by hand; the envs alone have them all."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

import mpg_envs
from mpg_envs.policies import registry
from mpg_envs.policies.oracle import OraclePolicy
from mpg_envs.policies.pixel_heuristic import PixelHeuristic, heuristic_grasp, heuristic_grasp_action
from mpg_envs.policies.random_policy import RandomPolicy
from mpg_envs.policies.registry import baseline_name, make_baseline, register_baseline, scripted_baseline_names

SIZE = 224


def _mask(rows: slice, cols: slice) -> np.ndarray:
    mask = np.zeros((SIZE, SIZE), np.uint8)
    mask[rows, cols] = 1
    return mask


def test_the_registry_names_the_four_scripted_baselines_each_with_a_line():
    assert scripted_baseline_names() == ("oracle", "random", "pixel-heuristic", "matcher")
    for entry in registry.SCRIPTED_BASELINES.values():
        assert entry.description and "\n" not in entry.description


def test_a_former_name_says_the_current_one_and_an_unknown_name_none():
    assert baseline_name("pixel-heuristic") == "pixel-heuristic"
    assert baseline_name("grasp-only") == "pixel-heuristic"
    assert baseline_name("shipped") is None and baseline_name("nope") is None


def test_a_taken_name_cannot_be_registered_again():
    with pytest.raises(ValueError, match="'random' is already registered"):
        register_baseline("random", lambda env, seed: RandomPolicy(env, seed), "again")
    with pytest.raises(ValueError, match="'grasp-only' is already registered"):
        register_baseline("other", lambda env, seed: RandomPolicy(env, seed), "again", old_names=("grasp-only",))
    assert "other" not in registry.SCRIPTED_BASELINES


def test_the_grasp_is_at_the_blob_centre_across_its_short_side():
    # 10 rows tall, 4 columns wide: the fingers close along the rows' direction (rotation 0) at
    # the centre (14.5, 21.5), snapped to the first nearest mask pixel (14, 21).
    assert heuristic_grasp({"mask": _mask(slice(10, 20), slice(20, 24))}) == (0, 14, 21)
    # The same turned a quarter: 4 rows, 10 columns: rotation 4 (90 degrees), centre (51.5, 104.5).
    assert heuristic_grasp({"mask": _mask(slice(50, 54), slice(100, 110))}) == (4, 51, 104)
    # A smaller second blob is ignored: the largest one is the target's footprint.
    two = _mask(slice(10, 20), slice(20, 24))
    two[100:103, 100:103] = 1
    assert heuristic_grasp({"mask": two}) == (0, 14, 21)


def test_the_grasp_as_a_flat_action_and_an_empty_mask_refused():
    obs = {"mask": _mask(slice(10, 20), slice(20, 24))}
    # grasp is the third primitive: 2 * 16 rotations * 224 * 224, then rotation 0, row 14, col 21.
    assert heuristic_grasp_action(obs, ("move", "push", "grasp")) == 2 * 16 * SIZE * SIZE + 14 * SIZE + 21
    with pytest.raises(ValueError, match="non-empty"):
        heuristic_grasp({"mask": np.zeros((SIZE, SIZE), np.uint8)})


def test_make_baseline_builds_each_and_the_former_name_warns_once():
    env = mpg_envs.make("MPG-Occluded-v0")
    try:
        assert isinstance(make_baseline("oracle", env), OraclePolicy)
        random_policy = make_baseline("random", env, seed=3)
        assert isinstance(random_policy, RandomPolicy) and random_policy.name == "random"
        heuristic = make_baseline("pixel-heuristic", env)
        assert isinstance(heuristic, PixelHeuristic) and heuristic.name == "pixel-heuristic"
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            first = make_baseline("grasp-only", env)
            make_baseline("grasp-only", env)
        assert isinstance(first, PixelHeuristic)
        assert [str(w.message) for w in caught if w.category is DeprecationWarning] in (
            ["the policy name 'grasp-only' is now 'pixel-heuristic'"],
            [],  # an earlier test of this process already heard it
        )
        with pytest.raises(ValueError, match="unknown scripted baseline 'nope'; valid: oracle, random, pixel-heuristic, matcher"):
            make_baseline("nope", env)
    finally:
        env.close()


def test_the_random_policy_draws_the_same_actions_from_the_same_seed():
    env = mpg_envs.make("MPG-Occluded-v0")
    try:
        a, b = RandomPolicy(env, seed=5), RandomPolicy(env, seed=9)
        b.seed(5)
        draws = [a.act({}) for _ in range(5)]
        assert draws == [b.act({}) for _ in range(5)]
        assert all(0 <= d < env.action_space.n for d in draws)
    finally:
        env.close()


def test_the_registry_loads_without_torch():
    code = (
        "import sys; from mpg_envs.policies.registry import scripted_baseline_names; "
        "assert scripted_baseline_names(); print('torch' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
