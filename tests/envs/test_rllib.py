"""mpg_envs.integrations.rllib: env_config parsing and seeding, then one short RLlib PPO iteration."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ray.rllib")

from ray.rllib.env.env_context import EnvContext  # noqa: E402

from mpg_envs import ENV_IDS  # noqa: E402
from mpg_envs.integrations.rllib import SEED_STRIDE, InitialSeed, make_env, register  # noqa: E402
from mpg_envs.integrations.wrappers import GridAction, ImageObservation  # noqa: E402


def test_env_config_builds_wrapped_env_with_constructor_args():
    ctx = EnvContext({"wrappers": ["grid", ["image", {"size": 42}]], "num_objects": 1, "seed": 5}, worker_index=3, vector_index=2)
    env = make_env("MPG-Stage2-v0", ctx)
    assert isinstance(env, InitialSeed) and env.initial_seed == 5 + 3 * SEED_STRIDE + 2
    assert env.unwrapped.num_objects == 1
    assert env.observation_space.shape == (42, 42, 5) and env.observation_space.dtype == np.float32
    assert env.action_space.n == 8 * 28 * 28
    chain = []
    while hasattr(env, "env"):
        chain.append(type(env))
        env = env.env
    assert chain.index(ImageObservation) < chain.index(GridAction)  # "grid" innermost
    env.close()


def test_new_api_stack_envs_of_one_runner_get_distinct_seeds():
    ctx = EnvContext({"num_objects": 1}, worker_index=917)  # one context for all of a runner's envs
    first, second = make_env("MPG-Stage2-v0", ctx), make_env("MPG-Stage2-v0", ctx)
    assert (first.initial_seed, second.initial_seed) == (917 * SEED_STRIDE, 917 * SEED_STRIDE + 1)
    obs, _ = first.reset()  # seeded from the index
    again, _ = second.reset(seed=first.initial_seed)  # a caller's seed wins
    np.testing.assert_array_equal(obs["depth"], again["depth"])
    first.close()
    second.close()


@pytest.mark.parametrize(
    "config, message",
    [
        ({"wrappers": "grid"}, "must be a list"),
        ({"wrappers": ["pixels"]}, "unknown wrapper 'pixels'"),
        ({"wrappers": [["grid", 8]]}, "unknown wrapper"),
        ({"seed": -1}, "non-negative integer"),
    ],
)
def test_bad_env_config_is_named(config, message):
    with pytest.raises(ValueError, match=message):
        make_env("MPG-Stage2-v0", config)


def test_unknown_id():
    with pytest.raises(ValueError, match="unknown MPG env 'MPG-Stage9-v0'"):
        make_env("MPG-Stage9-v0")


def test_one_rllib_ppo_iteration_on_wrapped_stage2():
    import ray
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.tune.registry import ENV_CREATOR, _global_registry

    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, ignore_reinit_error=True)
    try:
        assert register() == ENV_IDS
        assert all(_global_registry.contains(ENV_CREATOR, env_id) for env_id in ENV_IDS)
        config = (
            PPOConfig()
            .environment("MPG-Stage2-v0", env_config={"wrappers": [["grid", {"cell": 16}], ["image", {"size": 42}]], "num_objects": 1})
            .env_runners(num_env_runners=0, num_envs_per_env_runner=1, rollout_fragment_length=16)
            .learners(num_learners=0)
            .training(train_batch_size_per_learner=16, minibatch_size=16, num_epochs=1)
            .rl_module(model_config=DefaultModelConfig(conv_filters=[[8, [4, 4], 2], [16, [4, 4], 2], [16, [11, 11], 1, "valid"]], head_fcnet_hiddens=[32]))
            .debugging(seed=0)
        )
        algo = config.build_algo()
        try:
            result = algo.train()
            assert result["env_runners"]["num_env_steps_sampled_lifetime"] >= 16
            assert np.isfinite(result["learners"]["default_policy"]["total_loss"])
        finally:
            algo.stop()
    finally:
        ray.shutdown()
