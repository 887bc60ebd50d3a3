"""Seconds per training iteration on Stage 5 with the small network, on 2 cores.

One iteration = decide (the coordinated greedy decision, or exploration) + act (the
primitive and the new observation, inside ``env.step``) + store the transition + one
learning step (double-DQN target on a prioritised batch, backward, Adam). The first
``--warmup`` iterations (PyTorch picks its kernels then) are not counted. Goals
(:data:`GOALS_S`, mean seconds per iteration on 2 quiet cores): under 1 s (VPG needed about 5 s
per iteration on a GPU), and 0.25 s (not met on a CPU with exact double-DQN targets at replay
ratio 1: the documentation's "Training with actors" says where the time goes).
``--replay-ratio R`` learns as a run at that ratio does (R gradient steps per env step, the
fraction carried over), so an iteration's mean, not its median, is the figure to compare;
The nets are the shipped config's (``[net_config]`` of ``mpg_agents/checkpoints/mpgnet_train.toml``:
colour-free); ``--net-option KEY=VALUE`` sets an ``MPGNetConfig`` field over it
(``color_input=True``: the paper's colour trunks).
The last output line is one JSON object.

    python benchmarks/train_speed.py [--iterations 30] [--warmup 5] [--batch-size 2] [--replay-ratio 1] [--net-option color_input=True]
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time


import numpy as np  # noqa: E402
import torch  # noqa: E402

from mpg_agents.learning.learner import Learner  # noqa: E402
from mpg_agents.learning.train_config import TrainConfig  # noqa: E402
from td_step_speed import shipped_net_config  # noqa: E402  (the shipped nets, with --net-option over them)


GOALS_S = (1.0, 0.25)
"""Mean seconds per iteration on 2 quiet cores the benchmark checks, loosest first."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=30)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--batch-size", type=int, default=2)
    parser.add_argument("--variant", default="small")
    parser.add_argument("--replay-ratio", type=float, default=1.0)
    parser.add_argument("--net-option", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    net_config = shipped_net_config(args.net_option)
    cfg = TrainConfig(
        steps=10**9, variant=args.variant, batch_size=args.batch_size, torch_threads=2, replay_ratio=args.replay_ratio, net_config=net_config
    )
    with tempfile.TemporaryDirectory() as out:
        learner = Learner(cfg, "MPG-Stage5-v0", out, log=lambda s: None)
        env = learner.env
        parts: dict[str, list[float]] = {"decide_s": [], "env_step_s": [], "replay_s": [], "learn_s": [], "iteration_s": []}
        obs, _ = env.reset(seed=0)
        for k in range(args.warmup + args.iterations):
            t0 = time.perf_counter()
            action = learner.act(obs).action
            t1 = time.perf_counter()
            next_obs, reward, terminated, truncated, info = env.step(action)
            t2 = time.perf_counter()
            learner.replay.add(
                {k_: v[None] for k_, v in obs.items()}, {k_: v[None] for k_, v in next_obs.items()},
                np.array([[action]]), np.array([reward], np.float32), np.array([terminated], np.float32), [{}],
            )
            t3 = time.perf_counter()
            learner.learn_owed(1)
            learner.counters.iteration += 1
            t4 = time.perf_counter()
            obs = env.reset(seed=k + 1)[0] if terminated or truncated else next_obs
            if k >= args.warmup:
                for name, value in zip(parts, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t4 - t0)):
                    parts[name].append(value)
    med = {k: statistics.median(v) for k, v in parts.items()}
    mean = {k: statistics.fmean(v) for k, v in parts.items()}
    print(f"Stage 5, {args.variant} network {net_config or ''}, batch {args.batch_size}, replay ratio {args.replay_ratio:g}, "
          f"{torch.get_num_threads()} threads, {args.iterations} iterations")
    for name in med:
        print(f"  {name:12s} {med[name]:.3f} s (median), {mean[name]:.3f} s (mean)")
    for goal in GOALS_S:
        print(f"goal (at most {goal:g} s per iteration, mean) " + ("met" if mean["iteration_s"] <= goal else "NOT met"))
    print(json.dumps({
        "iteration_s": round(med["iteration_s"], 4), "iteration_mean_s": round(mean["iteration_s"], 4),
        "parts": {k: round(v, 4) for k, v in med.items() if k != "iteration_s"},
        "parts_mean": {k: round(v, 4) for k, v in mean.items() if k != "iteration_s"},
        "replay_ratio": args.replay_ratio, "net_config": net_config,
    }))


if __name__ == "__main__":
    main()
