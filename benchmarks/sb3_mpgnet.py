"""Stable-Baselines3's own DQN driving the project's ``MPGNetPolicy`` on ``MPG-Stage2-v0``.

Trains ``stable_baselines3.DQN(MPGNetPolicy, env, replay_buffer_class=SB3HeightmapReplayBuffer)``
(SB3's loop, SB3's gradient step, MPGNet's fully convolutional Q maps as the Q-network) for
``--steps`` env steps with ``mpg-train``'s settings where SB3 has one (learning rate 1e-4,
discount 0.5, batch 2, target sync every 100 steps, epsilon 0.5 to 0.1 over the run), from
fresh weights, on one torch thread. ``--algo mpgdqn`` trains
:class:`mpg_agents.sb3.MPGDQN` instead (SB3's loop, the project's gradient step and
prioritised replay). Then the greedy policy is evaluated with
:func:`mpg_agents.evaluation.evaluate.evaluate` on held-out seeds ``--eval-seed + k`` (training
draws its scenes from ``--seed``).

Prints the training time, env steps per second, the mean training return over successive fifths
of the training episodes, and the held-out task success with its Wilson 95% interval and mean
motions; saves the model as ``<out>/<algo>.zip`` and, with ``--json``, writes the figures (the
evaluation's full record under ``"eval"``). The last line of output is one JSON object.

    python benchmarks/sb3_mpgnet.py [--steps 600] [--episodes 100] [--eval-seed 500000] [--json J]

Quick check (a few minutes): ``--steps 30 --learning-starts 10 --episodes 3``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"  # before numpy / torch start their pools
if not os.environ.get("DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ENV_ID = "MPG-Stage2-v0"
ALGOS = ("dqn", "mpgdqn")


def build_model(algo: str, env, seed: int, learning_starts: int):
    """SB3's ``DQN`` on ``MPGNetPolicy`` with the project's replay buffer, or ``MPGDQN``; both
    with ``mpg-train``'s settings (:class:`mpg_agents.learning.train_config.TrainConfig`)."""
    from stable_baselines3 import DQN

    from mpg_agents import MPGDQN, MPGNetPolicy
    from mpg_agents.learning.train_config import TrainConfig
    from mpg_agents.sb3 import SB3HeightmapReplayBuffer

    c = TrainConfig()
    common = dict(learning_starts=learning_starts, train_freq=1, gradient_steps=1, seed=seed, device="cpu", verbose=0)
    if algo == "mpgdqn":
        return MPGDQN(MPGNetPolicy, env, **common)
    return DQN(
        MPGNetPolicy, env, replay_buffer_class=SB3HeightmapReplayBuffer,
        learning_rate=c.learning_rate, buffer_size=c.replay_capacity, batch_size=c.batch_size, gamma=c.gamma,
        target_update_interval=c.target_update_every, exploration_fraction=1.0,
        exploration_initial_eps=c.epsilon_start, exploration_final_eps=c.epsilon_end, **common,
    )


def episode_returns():
    """An SB3 callback keeping ``(env steps so far, return)`` of every training episode."""
    from stable_baselines3.common.callbacks import BaseCallback

    class Returns(BaseCallback):
        def __init__(self):
            super().__init__()
            self.episodes: list[tuple[int, float]] = []
            self._running = 0.0

        def _on_step(self) -> bool:
            self._running += float(self.locals["rewards"][0])
            if self.locals["dones"][0]:
                self.episodes.append((self.num_timesteps, self._running))
                self._running = 0.0
                if len(self.episodes) % 20 == 0:
                    recent = np.mean([r for _, r in self.episodes[-20:]])
                    print(f"  {self.num_timesteps} steps, {len(self.episodes)} episodes, mean return of the last 20: {recent:.2f}", flush=True)
            return True

    return Returns()


def fifths(episodes: list[tuple[int, float]]) -> list[dict]:
    """Mean training return over successive fifths of the training episodes."""
    chunks = [c for c in np.array_split(np.arange(len(episodes)), min(5, len(episodes))) if len(c)] if episodes else []
    return [{"until_step": episodes[c[-1]][0], "episodes": len(c), "mean_return": round(float(np.mean([episodes[i][1] for i in c])), 3)} for c in chunks]


class GreedySB3:
    """A trained SB3 model as an ``act(obs)`` policy (greedy: ``MPGNetPolicy``'s decision)."""

    def __init__(self, name: str, model):
        self.name, self.model = name, model

    def act(self, obs):
        return int(self.model.predict(obs, deterministic=True)[0])


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algo", choices=ALGOS, default="dqn", help="SB3's DQN (default) or MPGDQN (the project's gradient step)")
    parser.add_argument("--steps", type=int, default=600, help="training env steps")
    parser.add_argument("--learning-starts", type=int, default=100, help="env steps before the first gradient step")
    parser.add_argument("--episodes", type=int, default=100, help="held-out evaluation episodes")
    parser.add_argument("--seed", type=int, default=0, help="training seed")
    parser.add_argument("--eval-seed", type=int, default=500_000, help="first held-out episode's seed")
    parser.add_argument("--out", default="runs/sb3_mpgnet", help="folder for the trained model")
    parser.add_argument("--json", help="write the figures here")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.episodes < 1 or not 0 <= args.learning_starts < args.steps:
        parser.error("--steps and --episodes must be >= 1, and --learning-starts in [0, --steps)")
    import gymnasium as gym
    import torch

    import mpg_envs  # noqa: F401  (registers the envs)
    from mpg_agents.evaluation.evaluate import evaluate
    from mpg_envs.tasks.config import EnvConfig

    torch.set_num_threads(1)
    env = gym.make(ENV_ID, config=EnvConfig(raycast_threads=1))
    model = build_model(args.algo, env, args.seed, args.learning_starts)
    params = int(sum(p.numel() for p in model.q_net.parameters()))
    print(f"{args.algo} on MPGNetPolicy ({params:,} parameters): {args.steps} training steps on {ENV_ID}", flush=True)
    returns = episode_returns()
    start = time.perf_counter()
    model.learn(total_timesteps=args.steps, callback=returns)
    train_seconds = time.perf_counter() - start
    Path(args.out).mkdir(parents=True, exist_ok=True)
    model.save(Path(args.out) / f"{args.algo}.zip")
    curve = fifths(returns.episodes)
    print(f"trained in {train_seconds:.0f} s ({args.steps / train_seconds:.2f} env steps/s); mean training return by fifths: "
          + ", ".join(f"{p['mean_return']:.2f}" for p in curve), flush=True)
    start = time.perf_counter()
    result = evaluate(GreedySB3(f"SB3 {args.algo.upper()} + MPGNetPolicy, {args.steps} steps", model), env, args.episodes, args.eval_seed, progress=True)
    eval_seconds = time.perf_counter() - start
    env.close()
    print(result.table())
    summary = {
        "env": ENV_ID, "algo": args.algo, "policy": "MPGNetPolicy", "train_env_steps": int(model.num_timesteps),
        "learning_starts": args.learning_starts, "seed": args.seed, "parameters": params,
        "train_seconds": round(train_seconds, 1), "env_steps_per_s": round(args.steps / train_seconds, 3),
        "training_episodes": len(returns.episodes), "learning_curve": curve,
        "episodes": args.episodes, "eval_seed": args.eval_seed, "eval_seconds": round(eval_seconds, 1),
        "success_rate": result.task_success_rate, "success_ci95": [round(v, 3) for v in result.success_interval],
        "mean_motions": round(result.average_motions, 2), "torch_threads": 1,
        "load_average": [round(v, 2) for v in os.getloadavg()], "eval": result.to_dict(),
    }
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(summary, indent=1, sort_keys=True))
    print(json.dumps({k: v for k, v in summary.items() if k != "eval"}))
    return summary


if __name__ == "__main__":
    main()
