import pytest

from mpg_agents.acting.seeds import CALIBRATION_SEED_OFFSET, DEMONSTRATION_SEED_OFFSET, MAX_SKIPPED_SEEDS, RUN_SEED_STRIDE, episode_seed, reset_first_valid
from mpg_envs.scenes.generators import InvalidSceneError


def test_episode_seeds_by_hand():
    assert episode_seed(0, 0) == 0
    assert episode_seed(0, 7) == 7
    assert episode_seed(2, 5) == 2_000_011
    assert episode_seed(0, 0, demonstration=True) == 800_000
    assert episode_seed(1, 3, demonstration=True) == 1_800_006
    assert episode_seed(0, 4, calibration=True) == 900_004
    assert episode_seed(1, 3, calibration=True) == 1_900_006


def test_seed_zero_keeps_training_and_demonstrations_off_the_evaluation_seeds():
    """Table I's held-out seeds are 500000-500099 and the tuning seeds 700000-700049; a run
    of seed 0 with 10^5 training episodes and 10^4 demonstrations touches neither."""
    training = {episode_seed(0, k) for k in (0, 99_999)}
    demos = {episode_seed(0, i, demonstration=True) for i in (0, 9_999)}
    assert max(training) < 500_000 and min(demos) > 700_049
    assert max(demos) < RUN_SEED_STRIDE and DEMONSTRATION_SEED_OFFSET < RUN_SEED_STRIDE
    calibrations = {episode_seed(0, j, calibration=True) for j in (0, 9_999)}
    assert min(calibrations) > max(demos) and max(calibrations) < RUN_SEED_STRIDE == CALIBRATION_SEED_OFFSET + 100_003


def test_negative_episode_index_is_refused():
    with pytest.raises(ValueError, match="episode index must be >= 0"):
        episode_seed(0, -1)


def test_an_episode_is_a_demonstration_or_a_calibration():
    with pytest.raises(ValueError, match="not both"):
        episode_seed(0, 0, demonstration=True, calibration=True)


class _SceneFailsFor:
    """A stand-in env whose reset fails (no valid scene) for the seeds in ``bad``."""

    def __init__(self, bad: set[int]):
        self.bad, self.seeds = bad, []

    def reset(self, seed=None, options=None):
        self.seeds.append(seed)
        if seed in self.bad:
            raise InvalidSceneError(f"seed {seed}")
        return {"seed": seed}, {}


def test_reset_first_valid_passes_over_seeds_without_a_scene_and_reports_each():
    env, skipped = _SceneFailsFor({12, 13}), []
    obs, _, k = reset_first_valid(env, lambda j: 10 + j, 2, on_skip=lambda j, e: skipped.append(j))
    assert (obs["seed"], k, skipped, env.seeds) == (14, 4, [2, 3], [12, 13, 14])
    obs, _, k = reset_first_valid(env, lambda j: 10 + j, 0)
    assert (obs["seed"], k) == (10, 0)


def test_reset_first_valid_gives_up_after_a_long_run_of_invalid_seeds():
    env = _SceneFailsFor(set(range(MAX_SKIPPED_SEEDS + 1)))
    with pytest.raises(InvalidSceneError, match="seeds in a row from episode 0"):
        reset_first_valid(env, lambda j: j, 0)
