"""Env steps/s of one ``MPG-Stage5-v0`` against ``gymnasium.vector.AsyncVectorEnv`` workers.

Both run random valid actions (``action_space.sample()``) with ``raycast_threads=1`` and
count every motion; episode resets (a new scene is dropped: about as long as 4-8 motions)
happen inside the timed loop in both, as they do in training. The first reset is not timed.

What kept two workers from scaling (an earlier measurement: 2.41 -> 3.23 steps/s with two workers) and what this
benchmark does about it:

- threads: by default an env ray-casts with up to 2 threads, and numpy/torch may start an
  OpenMP/BLAS pool per process; two workers on two cores then fight over them. Each worker
  here runs one thread: ``raycast_threads=1`` and ``OMP_NUM_THREADS`` / ``MKL_NUM_THREADS``
  / ``OPENBLAS_NUM_THREADS`` = 1 set before numpy, MuJoCo or torch are imported (in this
  process, inherited by every worker), plus ``mpg_envs.threads.worker_init()`` in each
  worker. The env's own ray-cast default is 1 thread in any ``multiprocessing`` worker
  (and whenever ``OMP_NUM_THREADS``/``MPG_NUM_THREADS`` say 1), so a plain
  ``AsyncVectorEnv([lambda: gym.make(...)] * 2)`` is not oversubscribed either:
  ``--raycast-threads 0`` (the env's default) checks it.
- the start method: "forkserver" starts workers from a clean process (no copied thread
  pools or locks of the parent) at the cost of a slower start, which is not timed.
- lockstep: ``AsyncVectorEnv.step`` waits for the slowest worker, so a worker that resets
  (or runs a long move) while the other runs a short push leaves a core idle. Each worker
  reports its busy seconds in ``info["worker_seconds"]``; the benchmark prints the share
  of worker time lost to that wait ("lockstep efficiency"), which bounds the speed-up.
  It is the one loss a synchronous vector env cannot remove; more workers than cores
  (``--workers 4`` on 2 cores) let the OS run one worker while another waits.
- observation copies: with ``shared_memory=True`` (the default) each worker writes its
  224 x 224 observation (352 kB) to shared memory and the parent copies the batch once per
  step; the benchmark times that copy, to be set against a 100+ ms motion.

Prints the machine load before the run (``os.getloadavg``): measure on a quiet machine.
The last output line is one JSON object.

    python benchmarks/vector_speed.py [--steps 60] [--workers 2] [--context forkserver] [--raycast-threads 1]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_var] = "1"  # before numpy / MuJoCo / torch start their pools; workers inherit it
if not os.environ.get("DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")

import argparse  # noqa: E402
import functools  # noqa: E402
import copy  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

ENV_ID = "MPG-Stage5-v0"


class WorkerTimer(gym.Wrapper):
    """Puts the seconds this env spent in ``step``/``reset`` into ``info["worker_seconds"]``."""

    def reset(self, **kwargs):
        start = time.perf_counter()
        obs, info = self.env.reset(**kwargs)
        info["worker_seconds"] = time.perf_counter() - start
        return obs, info

    def step(self, action):
        start = time.perf_counter()
        obs, reward, terminated, truncated, info = self.env.step(action)
        info["worker_seconds"] = time.perf_counter() - start
        return obs, reward, terminated, truncated, info


def make_env(raycast_threads: int | None = 1) -> gym.Env:
    """One Stage-V env on one thread (module level, so any start method can pickle it)."""
    from mpg_envs.tasks.config import EnvConfig
    from mpg_envs.threads import worker_init

    worker_init()  # one thread (OpenMP, torch if loaded); the workers' parallelism is their number

    return WorkerTimer(gym.make(ENV_ID, config=EnvConfig(raycast_threads=raycast_threads)))


def run_single(steps: int, seed: int, raycast_threads: int | None) -> dict:
    """``steps`` motions; a finished episode is reset before the next motion, as the
    vector env's next-step autoreset does."""
    env = make_env(raycast_threads)
    env.action_space.seed(seed)
    env.reset(seed=seed)
    resets = 0
    done = False
    start = time.perf_counter()
    for _ in range(steps):
        if done:
            env.reset()
            resets += 1
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        done = terminated or truncated
    seconds = time.perf_counter() - start
    env.close()
    return {"steps": steps, "seconds": seconds, "steps_per_s": steps / seconds, "resets": resets}


def run_vector(steps: int, workers: int, seed: int, context: str | None, shared_memory: bool, raycast_threads: int | None) -> dict:
    """``steps`` motions per worker (resets, which take a vector step of their own with
    Gymnasium 1.x's next-step autoreset, are not counted as motions)."""
    envs = gym.vector.AsyncVectorEnv(
        [functools.partial(make_env, raycast_threads)] * workers, shared_memory=shared_memory, context=context
    )
    envs.action_space.seed(seed)
    envs.reset(seed=seed)
    motions = resets = 0
    busy = waited = 0.0
    autoreset = np.zeros(workers, bool)
    start = time.perf_counter()
    while motions < steps * workers:
        _, _, terminated, truncated, info = envs.step(envs.action_space.sample())
        motions += int((~autoreset).sum())
        resets += int(autoreset.sum())
        seconds = np.asarray(info["worker_seconds"], float)
        busy += seconds.sum()
        waited += seconds.max() * workers
        autoreset = np.logical_or(terminated, truncated)
    seconds = time.perf_counter() - start
    # What the parent spends per step copying the batch of observations (step's deepcopy).
    copy_start = time.perf_counter()
    for _ in range(20):
        copy.deepcopy(envs.observations)
    copy_ms = (time.perf_counter() - copy_start) / 20 * 1000
    envs.close()
    return {
        "steps": motions,
        "resets": resets,
        "seconds": seconds,
        "steps_per_s": motions / seconds,
        "lockstep_efficiency": busy / waited if waited else None,
        "observation_copy_ms": copy_ms,
    }


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=60, help="motions per env (the single env, and each worker)")
    parser.add_argument("--raycast-threads", type=int, default=1, help="heightmap threads per env (0: the env's default, up to 2)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--context", default="forkserver", choices=["fork", "forkserver", "spawn"])
    parser.add_argument("--no-shared-memory", action="store_true")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if args.steps < 1 or args.workers < 1:
        parser.error("--steps and --workers must be >= 1")

    load = os.getloadavg()
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"machine: {cores} cores, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (1, 5, 15 min) before the run", flush=True)
    threads = args.raycast_threads or None
    single = run_single(args.steps, args.seed, threads)
    print(f"1 env:            {single['steps_per_s']:.2f} steps/s ({single['steps']} motions, {single['resets']} resets, {single['seconds']:.1f} s)", flush=True)
    vector = run_vector(args.steps, args.workers, args.seed, args.context, not args.no_shared_memory, threads)
    ratio = vector["steps_per_s"] / single["steps_per_s"]
    print(
        f"{args.workers} workers ({args.context}): {vector['steps_per_s']:.2f} steps/s ({vector['steps']} motions, {vector['resets']} resets, "
        f"{vector['seconds']:.1f} s); lockstep efficiency {vector['lockstep_efficiency']:.2f}",
        flush=True,
    )
    print(f"observation batch copy in the parent: {vector['observation_copy_ms']:.2f} ms per step", flush=True)
    print(f"speed-up {ratio:.2f}x on {args.workers} workers (ideal {min(args.workers, cores)}x)", flush=True)
    summary = {
        "env": ENV_ID,
        "cores": cores,
        "load_before": [round(v, 2) for v in load],
        "context": args.context,
        "raycast_threads": threads,
        "single": single,
        "vector": vector,
        "workers": args.workers,
        "speedup": ratio,
    }
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    main()
