"""RLlib PPO on the wrapped ``MPG-Stage2-v0``: a few iterations with env runners on Ray.

The env is ``ImageObservation(GridAction(MPG-Stage2-v0))`` built by
``mpg_envs.integrations.rllib.register()`` from ``env_config`` (``{"wrappers": ["grid", "image"]}``):
an 84 x 84 x 5 channels-last image and 6,272 grid actions. RLlib's new API stack builds a
CNN encoder for any 3-D ``Box`` observation; the channel count (5) comes from the space,
and ``conv_filters`` below end in one "valid" 11 x 11 convolution so the encoder gives a
64-vector (RLlib's own 84 x 84 default keeps an 11 x 11 x 256 map, 31k features).

Local run (starts a Ray instance on this machine)::

    python benchmarks/rllib_ppo.py --iterations 3 --env-runners 2

On a cluster: start Ray there (``ray start --head`` on the head node, ``ray start
--address=<head>:6379`` on the others), install this package on every node, then run
this script on the head node with ``--address auto`` (or from outside through Ray Client,
``--address ray://<head>:10001``) and raise ``--env-runners`` to the number of free CPUs:
each env runner is one process with one env and one CPU, so env steps/s grow with them.

Prints, per iteration, the mean episode return, the env steps sampled and the wall time;
the last output line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

CONV_FILTERS = {
    84: [[16, [8, 8], 4], [32, [4, 4], 2], [64, [11, 11], 1, "valid"]],  # 84 -> 21 -> 11 -> 1
    42: [[16, [4, 4], 2], [32, [4, 4], 2], [64, [11, 11], 1, "valid"]],  # 42 -> 21 -> 11 -> 1
}
"""Encoder filters per image size ([channels, kernel, stride(, padding)]; "same" by default)."""


def ppo_config(args: argparse.Namespace):
    """The PPO config of this example (new API stack)."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    env_config = {
        "wrappers": [["grid", {"cell": args.cell, "rotations": 8}], ["image", {"size": args.size}]],
        "seed": args.seed,
    }
    return (
        PPOConfig()
        .environment(args.env, env_config=env_config)
        .env_runners(
            num_env_runners=args.env_runners,
            num_envs_per_env_runner=1,
            num_cpus_per_env_runner=1,
            rollout_fragment_length="auto",
        )
        .learners(num_learners=0)
        .training(
            train_batch_size_per_learner=args.batch,
            minibatch_size=min(64, args.batch),
            num_epochs=2,
            lr=3e-4,
        )
        .rl_module(model_config=DefaultModelConfig(conv_filters=CONV_FILTERS[args.size], head_fcnet_hiddens=[256]))
        .debugging(seed=args.seed)
    )


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--iterations", type=int, default=3)
    parser.add_argument("--env-runners", type=int, default=2, help="env runner processes (0: sample in the driver)")
    parser.add_argument("--batch", type=int, default=256, help="env steps per training iteration")
    parser.add_argument("--env", default="MPG-Stage2-v0")
    parser.add_argument("--size", type=int, default=84, choices=sorted(CONV_FILTERS), help="image side")
    parser.add_argument("--cell", type=int, default=8, help="GridAction cell (pixels)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--address", default=None, help="Ray cluster address ('auto', 'ray://host:10001'); default: a local Ray")
    args = parser.parse_args(argv)
    if args.iterations < 1 or args.batch < 1 or args.env_runners < 0:
        parser.error("--iterations and --batch must be >= 1, --env-runners >= 0")

    import ray

    from mpg_envs.integrations.rllib import register

    ray.init(address=args.address, include_dashboard=False, log_to_driver=False, ignore_reinit_error=True)
    register()
    start = time.perf_counter()
    algo = ppo_config(args).build_algo()
    build_s = time.perf_counter() - start
    params = sum(p.numel() for p in algo.get_module().parameters())
    print(f"RLlib PPO on {args.env}: {params:,} parameters, {args.env_runners} env runners, built in {build_s:.1f} s", flush=True)
    rows = []
    for i in range(args.iterations):
        t = time.perf_counter()
        result = algo.train()
        runners = result.get("env_runners", {})
        row = {
            "iteration": i + 1,
            "episode_return_mean": runners.get("episode_return_mean"),
            "episodes": runners.get("num_episodes_lifetime"),
            "env_steps": runners.get("num_env_steps_sampled_lifetime"),
            "seconds": round(time.perf_counter() - t, 2),
        }
        rows.append(row)
        ret = row["episode_return_mean"]
        ret_text = "n/a (no episode ended yet)" if ret is None or ret != ret else f"{ret:.3f}"
        print(f"iteration {row['iteration']}: return {ret_text}, {row['env_steps']} env steps so far, {row['seconds']:.1f} s", flush=True)
    total = time.perf_counter() - start - build_s
    steps = rows[-1]["env_steps"] or 0
    algo.stop()
    ray.shutdown()
    summary = {
        "env": args.env,
        "parameters": params,
        "env_runners": args.env_runners,
        "iterations": rows,
        "env_steps_per_s": round(steps / total, 3) if total > 0 else None,
    }
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    main()
