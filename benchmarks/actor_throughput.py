"""Env steps and gradient steps per second of training with 1, 2, ... actors, on this machine.

For each actor count a fresh Stage V run (small network, the default settings, checkpoints
off while it is measured) trains for ``--seconds`` after ``--warmup`` iterations (the actors'
start-up, PyTorch picking its kernels) and is stopped; the rates are counted between the
two. Gradient steps are the learner's TD steps (``trained_steps``: those
whose batch held a sample of a branch learning then, the count the target sync and the
weights refresh follow). One actor acts in the learner's process (no Ray, no actor process); more actors step
their own envs in their own processes on the chosen backend, the learner learning in this one
at ``--replay-ratio`` gradient steps per env step. The machine (CPU count, model, load when
each run began) is printed; nothing else should run beside it for quiet numbers.
The last output line is one JSON object.

    python benchmarks/actor_throughput.py --actors 1 2 [--backend processes|ray] [--seconds 60]
        [--replay-ratio 1.0] [--device cpu|cuda|auto] [--env MPG-Stage5-v0]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from typing import Any

from mpg_agents.learning.learner import Learner
from mpg_agents.learning.train_config import TrainConfig
from mpg_agents.learning.training_stages import stage_for_env


def cpu_model() -> str:
    """The CPU's model name (Linux), else the platform's processor string."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


class TimedLearner(Learner):
    """A learner that notes when each iteration was recorded and ends the run ``seconds`` after
    its ``warmup``-th iteration (the budget set to the iterations done: the actors' steps in
    flight are dropped, as at a run's end)."""

    def __init__(self, *args: Any, warmup: int, seconds: float, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.warmup, self.seconds = warmup, seconds
        self.mark: tuple[float, int, int, int] | None = None  # (time, iteration, TD steps, trained steps) after the warm-up
        self.last: tuple[float, int, int, int] | None = None
        self.td_steps = 0  # every TD step taken (one whose batch holds no sample of a branch learning now trains nothing)

    def learn(self) -> float:
        self.td_steps += 1
        return super().learn()

    def record(self, *args: Any) -> None:
        super().record(*args)
        c, now = self.counters, time.perf_counter()
        if c.iteration == self.warmup:
            self.mark = (now, c.iteration, self.td_steps, c.gradient_steps)
        if self.mark is not None:
            self.last = (now, c.iteration, self.td_steps, c.gradient_steps)
            if now - self.mark[0] >= self.seconds:
                self.steps = c.iteration


def measure(actors: int, args: argparse.Namespace) -> dict[str, Any]:
    cfg = TrainConfig(
        steps=10**6, actors=actors, actor_backend=args.backend, replay_ratio=args.replay_ratio, device=args.device,
        torch_threads=args.learner_threads, checkpoint_every=10**6, seed=args.seed,
    )
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        learner = TimedLearner(cfg, stage_for_env(args.env), out, log=lambda s: None, warmup=args.warmup, seconds=args.seconds)
        learner.run()
        total = time.perf_counter() - start
    if learner.mark is None or learner.last is None or learner.last[1] == learner.mark[1]:
        raise RuntimeError(f"{actors} actors: fewer than {args.warmup + 1} iterations; give more --seconds")
    (t0, i0, g0, k0), (t1, i1, g1, k1) = learner.mark, learner.last
    return {
        "actors": actors, "backend": "in-process" if actors == 1 else args.backend, "env_steps": i1 - i0, "gradient_steps": g1 - g0,
        "trained_steps": k1 - k0, "seconds": round(t1 - t0, 2), "env_steps_per_s": round((i1 - i0) / (t1 - t0), 3),
        "gradient_steps_per_s": round((g1 - g0) / (t1 - t0), 3), "wall_s_with_startup": round(total, 1), "load_at_start": round(load, 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--actors", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--backend", choices=("ray", "processes"), default="processes")
    parser.add_argument("--seconds", type=float, default=60.0, help="measured seconds per actor count")
    parser.add_argument("--warmup", type=int, default=5, help="iterations before the clock starts")
    parser.add_argument("--replay-ratio", type=float, default=1.0)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--learner-threads", type=int, default=1, help="torch threads of the learner")
    parser.add_argument("--env", default="MPG-Stage5-v0")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    machine = {"cpus": os.cpu_count(), "usable_cpus": len(os.sched_getaffinity(0)), "cpu_model": cpu_model()}
    print(f"machine: {machine['cpus']} CPUs ({machine['usable_cpus']} usable), {machine['cpu_model']}; env {args.env}, "
          f"replay ratio {args.replay_ratio}, device {args.device}, learner threads {args.learner_threads}")
    rows = []
    for n in args.actors:
        rows.append(measure(n, args))
        print(json.dumps(rows[-1]), flush=True)
    print(f"\n{'actors':>6} {'backend':>10} {'env steps/s':>12} {'grad steps/s':>13} {'env steps':>9} {'s':>6} {'load':>5}")
    for r in rows:
        print(f"{r['actors']:>6} {r['backend']:>10} {r['env_steps_per_s']:>12.3f} {r['gradient_steps_per_s']:>13.3f} "
              f"{r['env_steps']:>9} {r['seconds']:>6.1f} {r['load_at_start']:>5.2f}")
    print(json.dumps({"machine": machine, "env": args.env, "replay_ratio": args.replay_ratio, "device": args.device, "rows": rows}))


if __name__ == "__main__":
    main()
