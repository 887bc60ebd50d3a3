"""Third-party baselines on ``MPG-Stage2-v0``: SB3 PPO and DQN beside the built-in policies.

Trains SB3's PPO and DQN with ``CnnPolicy`` through the standard wrappers,
``ImageObservation(GridAction(env))`` (an 84 x 84 x 5 image; 6,272 grid actions: 8 x 8
pixel cells x 8 grasp angles), for a fixed budget of env steps on a ``SubprocVecEnv``
(``--envs`` workers, one torch/OpenMP thread and ``raycast_threads=1`` each). Then it
evaluates each trained model, and the built-in ``random``, ``pixel-heuristic`` and ``shipped``
(MPGNet) policies on the raw env, with ``mpg_agents.evaluation.evaluate.evaluate``: the same
episodes for all, seeded ``--eval-seed + k`` (held out: training envs draw scenes from
``--seed + worker``).

Prints one table: parameters, training env steps/s, peak memory (RSS of the trainer and
all its worker processes, sampled every 0.2 s), task success with a Wilson 95% interval,
mean motions per episode; and, per algorithm, its learning curve (mean training return
over successive fifths of its training episodes: does it learn?). Saves the trained models as ``<out>/ppo.zip`` and
``<out>/dqn.zip`` (and every 10,000 steps under ``<out>/<algo>_checkpoints/``), and each
training episode's return as ``<out>/<algo>_episodes.csv``. The last output line is one JSON object.

    python benchmarks/third_party.py [--steps 20000] [--envs N] [--episodes 50] [--out runs/third_party]

Quick check (a minute or two): ``--steps 256 --episodes 3 --envs 2``. A saved model (e.g. a
checkpoint of a run that was stopped) is evaluated alone with ``--algos ppo --load PATH``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"  # before numpy / torch start their pools; SubprocVecEnv workers inherit it
if not os.environ.get("DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")

import argparse  # noqa: E402
import functools  # noqa: E402
import json  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

ENV_ID = "MPG-Stage2-v0"
ALGOS = ("ppo", "dqn")
BASELINES = ("random", "pixel-heuristic", "shipped")


# ----------------------------------------------------------------------------- envs
def make_wrapped_env(cell: int, size: int, action: str = "grid") -> gym.Env:
    """``ImageObservation(GridAction(MPG-Stage2-v0))`` (or ``ContinuousAction`` for
    ``action="continuous"``) on one thread (picklable for workers)."""
    from mpg_envs.tasks.config import EnvConfig
    from mpg_envs.threads import worker_init
    from mpg_envs.integrations.wrappers import ContinuousAction, GridAction, ImageObservation

    worker_init()  # one thread: the workers' parallelism is their number
    env = gym.make(ENV_ID, config=EnvConfig(raycast_threads=1))
    env = GridAction(env, cell=cell) if action == "grid" else ContinuousAction(env)
    return ImageObservation(env, size=size)


def make_training_envs(n: int, cell: int, size: int, action: str = "grid"):
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecMonitor

    # forkserver: workers start clean, not as copies of a trainer that has torch loaded.
    envs = SubprocVecEnv([functools.partial(make_wrapped_env, cell, size, action)] * n, start_method="forkserver")
    return VecMonitor(envs)


# ----------------------------------------------------------------------------- memory
def _tree_rss_bytes(root: int) -> int:
    """Resident memory of ``root`` and all its descendants (Linux ``/proc``)."""
    parents: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    parents[int(entry)] = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue  # the process ended meanwhile
    tree, frontier = {root}, [root]
    while frontier:
        pid = frontier.pop()
        children = [c for c, p in parents.items() if p == pid and c not in tree]
        tree.update(children)
        frontier.extend(children)
    total = 0
    for pid in tree:
        try:
            with open(f"/proc/{pid}/statm") as f:
                total += int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, IndexError, ValueError):
            continue
    return total


class PeakMemory:
    """Samples the RSS of this process tree in a thread; ``peak`` in bytes."""

    def __init__(self, interval: float = 0.2):
        self.interval, self.peak = interval, 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, _tree_rss_bytes(os.getpid()))
            self._stop.wait(self.interval)

    def __enter__(self) -> "PeakMemory":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, _tree_rss_bytes(os.getpid()))


# ----------------------------------------------------------------------------- training
def build_model(algo: str, envs, steps: int, seed: int):
    """SB3 PPO or DQN with ``CnnPolicy``; hyperparameters sized to the step budget."""
    from stable_baselines3 import DQN, PPO

    n = envs.num_envs
    if algo == "ppo":
        # Short rollouts, many updates: PPO's clip lets one update raise an action's probability
        # by at most ~1.2x, and a 6,272-way head needs many such updates to commit to the
        # target's cell (128-step rollouts and ent_coef 0.01 left the 20k-step return flat).
        # gamma 0.5 is the paper's: a grasp's reward comes on its own step.
        n_steps = max(8, min(64, steps // n))
        return PPO("CnnPolicy", envs, n_steps=n_steps, batch_size=min(64, n_steps * n), n_epochs=4,
                   learning_rate=3e-4, gamma=0.5, ent_coef=0.0, seed=seed, device="cpu", verbose=0)
    # DQN: a replay of up to 10k images (uint8, next observation not stored twice).
    return DQN("CnnPolicy", envs, buffer_size=max(100, min(steps, 10_000)), learning_starts=min(1000, steps // 4),
               batch_size=32, train_freq=max(1, 4 // n), gradient_steps=1, target_update_interval=max(1, min(1000, steps // 10)),
               exploration_fraction=0.5, exploration_final_eps=0.05, learning_rate=1e-4,
               optimize_memory_usage=True, replay_buffer_kwargs={"handle_timeout_termination": False},
               seed=seed, device="cpu", verbose=0)


def episode_recorder(name: str = "", total_steps: int = 0, reports: int = 10):
    """An SB3 callback keeping ``(env steps so far, return)`` of every training episode, and
    printing progress ``reports`` times over ``total_steps`` (steps/s, recent return), so a
    long run that is stopped still says how far it got."""
    from stable_baselines3.common.callbacks import BaseCallback

    class EpisodeRecorder(BaseCallback):
        def __init__(self):
            super().__init__()
            self.episodes: list[tuple[int, float]] = []
            self._every = max(1, total_steps // reports) if total_steps else 0
            self._next = self._every
            self._start = time.perf_counter()

        def _on_step(self) -> bool:
            for info in self.locals["infos"]:
                if "episode" in info:  # VecMonitor's summary of a finished episode
                    self.episodes.append((self.num_timesteps, float(info["episode"]["r"])))
            if self._every and self.num_timesteps >= self._next:
                self._next += self._every
                rate = self.num_timesteps / (time.perf_counter() - self._start)
                recent = [r for _, r in self.episodes[-20:]]
                mean = f"{np.mean(recent):.2f}" if recent else "-"
                print(f"{name}: {self.num_timesteps}/{total_steps} steps, {rate:.2f} steps/s, "
                      f"{len(self.episodes)} episodes, mean return of the last 20: {mean}", flush=True)
            return True

    return EpisodeRecorder()


def learning_curve(episodes: list[tuple[int, float]], parts: int = 5) -> list[dict]:
    """Mean training return in ``parts`` consecutive, equal shares of the episodes (on
    Stage II the return is 1 for a grasped target: the share of successful episodes)."""
    if not episodes:
        return []
    chunks = [c for c in np.array_split(np.arange(len(episodes)), min(parts, len(episodes))) if len(c)]
    return [
        {"until_step": episodes[c[-1]][0], "episodes": len(c), "mean_return": round(float(np.mean([episodes[i][1] for i in c])), 3)}
        for c in chunks
    ]


def train(algo: str, args: argparse.Namespace) -> tuple[object, dict]:
    import torch
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    torch.set_num_threads(1)
    recorder = episode_recorder(algo, args.steps)
    stem = algo if args.action == "grid" else f"{algo}_{args.action}"  # the saved model's, and its checkpoints' prefix
    with PeakMemory() as memory:
        envs = make_training_envs(args.envs, args.cell, args.size, args.action)
        model = build_model(algo, envs, args.steps, args.seed)
        start = time.perf_counter()
        # A model every 10,000 steps, so a long run that is stopped still leaves one to evaluate.
        keeper = CheckpointCallback(save_freq=max(1, 10_000 // args.envs), save_path=str(Path(args.out) / f"{algo}_checkpoints"),
                                    name_prefix=stem)
        model.learn(total_timesteps=args.steps, callback=CallbackList([recorder, keeper]))
        seconds = time.perf_counter() - start
        envs.close()
    params = sum(p.numel() for p in model.policy.parameters())
    path = Path(args.out) / f"{stem}.zip"
    model.save(path)
    # Every training episode, to plot the learning curve at any resolution.
    with open(path.with_name(path.stem + "_episodes.csv"), "w") as f:
        f.write("env_steps,return\n" + "".join(f"{step},{ret:g}\n" for step, ret in recorder.episodes))
    return model, {
        "parameters": int(params),
        "train_env_steps": int(model.num_timesteps),
        "train_seconds": round(seconds, 1),
        "env_steps_per_s": round(model.num_timesteps / seconds, 2),
        "peak_rss_mb": round(memory.peak / 2**20),
        "model": str(path),
        "learning_curve": learning_curve(recorder.episodes),
    }


def load(algo: str, path: str) -> tuple[object, dict]:
    """A saved model (``<out>/ppo.zip`` or a checkpoint under ``<out>/ppo_checkpoints/``) to
    evaluate without training; its row has no speed or memory figures."""
    from stable_baselines3 import DQN, PPO

    if not Path(path).is_file():
        raise FileNotFoundError(f"no saved model at {path!r}")
    model = (PPO if algo == "ppo" else DQN).load(path, device="cpu")
    params = sum(p.numel() for p in model.policy.parameters())
    return model, {"parameters": int(params), "train_env_steps": int(model.num_timesteps), "env_steps_per_s": None,
                   "peak_rss_mb": None, "model": path}


class SB3Policy:
    """A trained SB3 model as an ``act(obs)`` policy (greedy) for ``evaluate``."""

    def __init__(self, name: str, model):
        self.name, self.model = name, model

    def act(self, obs):
        return self.model.predict(obs, deterministic=True)[0]


# ----------------------------------------------------------------------------- evaluation
def evaluate_row(policy, env: gym.Env, args: argparse.Namespace) -> dict:
    from scipy.stats import binomtest

    from mpg_agents.evaluation.evaluate import evaluate

    result = evaluate(policy, env, args.episodes, args.eval_seed)
    successes = int(round(result.task_success_rate * args.episodes))
    interval = binomtest(successes, args.episodes).proportion_ci(confidence_level=0.95, method="wilson")
    return {
        "success_rate": result.task_success_rate,
        "success_ci95": [round(float(interval.low), 3), round(float(interval.high), 3)],
        "mean_motions": round(result.average_motions, 2),
        "episodes": args.episodes,
    }


def table(rows: dict[str, dict]) -> str:
    header = f"{'policy':<12} {'parameters':>11} {'env steps/s':>11} {'peak MB':>8} {'success [95% CI]':>22} {'motions':>7}"
    lines = [header, "-" * len(header)]
    for name, r in rows.items():
        params = f"{r['parameters']:,}" if r.get("parameters") is not None else "-"
        speed = f"{r['env_steps_per_s']:.2f}" if r.get("env_steps_per_s") is not None else "-"
        memory = str(r["peak_rss_mb"]) if r.get("peak_rss_mb") is not None else "-"
        lo, hi = r["success_ci95"]
        success = f"{100 * r['success_rate']:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}]"
        lines.append(f"{name:<12} {params:>11} {speed:>11} {memory:>8} {success:>22} {r['mean_motions']:>7.2f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=20_000, help="training env steps per algorithm")
    parser.add_argument("--envs", type=int, default=len(os.sched_getaffinity(0)), help="SubprocVecEnv workers (default: cores)")
    parser.add_argument("--episodes", type=int, default=50, help="evaluation episodes per policy")
    parser.add_argument("--algos", default=",".join(ALGOS), help=f"comma-separated, of {ALGOS}")
    parser.add_argument("--baselines", default=",".join(BASELINES), help=f"comma-separated, of {BASELINES} (empty: none)")
    parser.add_argument("--cell", type=int, default=8, help="GridAction cell in pixels")
    parser.add_argument("--size", type=int, default=84, help="ImageObservation side in pixels")
    parser.add_argument("--action", choices=("grid", "continuous"), default="grid",
                        help="GridAction (PPO, DQN) or ContinuousAction (PPO only: x, y, angle, primitive scores)")
    parser.add_argument("--load", help="evaluate this saved model (one algorithm in --algos) instead of training one")
    parser.add_argument("--seed", type=int, default=0, help="training seed")
    parser.add_argument("--eval-seed", type=int, default=100_000, help="first evaluation episode's seed (held out)")
    parser.add_argument("--out", default="runs/third_party", help="folder for the trained models")
    args = parser.parse_args(argv)
    algos = [a for a in args.algos.split(",") if a]
    baselines = ["pixel-heuristic" if b == "grasp-only" else b for b in args.baselines.split(",") if b]  # its former name
    bad = [a for a in algos if a not in ALGOS] + [b for b in baselines if b not in BASELINES]
    if bad or args.steps < 1 or args.envs < 1 or args.episodes < 1:
        parser.error(f"--steps, --envs, --episodes must be >= 1; algorithms from {ALGOS}, baselines from {BASELINES} (got {bad})")
    if args.load and len(algos) != 1:
        parser.error(f"--load evaluates one saved model: give one algorithm in --algos (got {algos})")
    if args.action == "continuous" and "dqn" in algos:
        parser.error("DQN needs a discrete action space: --action continuous takes --algos ppo")
    Path(args.out).mkdir(parents=True, exist_ok=True)

    import torch

    import mpg_envs  # noqa: F401
    from mpg_agents.evaluation.policy_zoo import make_policy
    from mpg_envs.tasks.config import EnvConfig

    torch.set_num_threads(1)
    rows: dict[str, dict] = {}
    what = f"the saved {args.load}" if args.load else f"{args.steps} training steps per algorithm on {args.envs} workers"
    print(f"{ENV_ID}: {what}; {args.episodes} evaluation episodes from seed {args.eval_seed}", flush=True)
    for algo in algos:
        if args.load:
            model, row = load(algo, args.load)
            print(f"{algo}: loaded {row['model']} ({row['train_env_steps']} training steps, {row['parameters']:,} parameters)", flush=True)
        else:
            model, row = train(algo, args)
            print(f"{algo}: trained {row['train_env_steps']} steps in {row['train_seconds']} s ({row['env_steps_per_s']} steps/s), "
                  f"{row['parameters']:,} parameters, peak {row['peak_rss_mb']} MB; saved {row['model']}", flush=True)
            curve = ", ".join(f"{p['mean_return']:.2f} (to step {p['until_step']})" for p in row["learning_curve"])
            print(f"{algo}: mean training return over successive fifths of its episodes: {curve or 'no episode ended'}", flush=True)
        wrapped = make_wrapped_env(args.cell, args.size, args.action)  # after training: not in its peak memory
        row.update(evaluate_row(SB3Policy(algo, model), wrapped, args))
        wrapped.close()
        rows[algo if args.action == "grid" else f"{algo}-{args.action}"] = row
    raw = gym.make(ENV_ID, config=EnvConfig(raycast_threads=1))
    for name in baselines:
        policy = make_policy(name, raw, seed=args.eval_seed)
        params = None
        if hasattr(policy, "policy"):
            params = int(sum(p.numel() for p in policy.policy.parameters()))
        rows[name] = {"parameters": params, "env_steps_per_s": None, "peak_rss_mb": None, **evaluate_row(policy, raw, args)}
    raw.close()
    print(table(rows))
    summary = {"env": ENV_ID, "action": args.action, "steps": None if args.load else args.steps, "loaded": args.load, "envs": args.envs, "episodes": args.episodes, "eval_seed": args.eval_seed, "rows": rows}
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    main()
