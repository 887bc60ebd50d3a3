"""Speed and memory of the MPGNet policy on CPU, quiet and on a busy machine.

Measures, for the ``small`` and ``large`` variants:

- ``decision_s``: median wall time of one full coordinated decision (``policy.predict``) on a
  Stage-5-like observation in the worst case the workflow has: target not occluded and not
  graspable, so the mask trunk, the grasp net and the push net all run (16 rotations each,
  batched);
- ``sequential_s``: the same work with the 16 rotations run one at a time (VPG's way: the
  observation normalised once, then per rotation resample, mask trunk, both branches);
- ``speedup``: median over rounds of sequential / batched (the two run in turn each round);
- ``conv_s`` / ``sequential_conv_s``: CPU time spent inside the trunks' convolutions per
  decision on each path (torch profiler), to tell trunk compute from resampling and overhead;
- ``train_step_s``: one training step, a batch of 4 on the grasp branch (chosen rotation only),
  Huber loss, backward, Adam step;
- ``loaded_decision_s`` / ``loaded_ratio`` (first variant): the decision while ``--busy``
  busy-looping processes share the cores, and its ratio to the quiet decision (4.0
  before the thread choice and passive OpenMP waiting of :mod:`mpg_envs.threads`; target
  <= 2.5). Fair sharing of 2 cores among this process and two loops gives 1.5-2x;

and the replay buffer's bytes per transition against SB3's ``DictReplayBuffer`` (real
``nbytes`` of both after adding the same transitions).

Observations come from ``MPG-Stage5-v0`` when it can be built, else from a synthetic scene.
Threads are chosen as the CLIs choose them (:func:`mpg_envs.threads.set_torch_threads`: the
free cores, ``MPG_NUM_THREADS`` or ``OMP_NUM_THREADS``) unless ``--threads`` fixes them.
Usage: ``python benchmarks/policy_speed.py [--repeats N] [--variants small large] [--threads N] [--busy 2]``.
The last line of output is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import statistics
import time
from typing import Any, Callable

import numpy as np

from mpg_envs.threads import THREADS_ENV, load_average, set_torch_threads, use_passive_openmp_wait

use_passive_openmp_wait()  # before torch loads OpenMP, as importing mpg_agents does

from mpg_envs.tasks.env import observation_space  # noqa: E402
import torch  # noqa: E402
from stable_baselines3.common.buffers import DictReplayBuffer  # noqa: E402
from torch.nn import functional as F  # noqa: E402

from mpg_agents.network.mpgnet import MPGNet, recompute_batch_norm_statistics
from mpg_agents.network.regions import region_max
from mpg_agents.sb3 import MPGNetPolicy
from mpg_agents.learning.replay import PrioritizedHeightmapReplayBuffer, sb3_dict_buffer_nbytes
from mpg_envs.grid.actions import PRIMITIVES, PixelActionSpace

SIZE = 224


def synthetic_scene(rng: np.random.Generator, blocks: int = 10) -> dict[str, np.ndarray]:
    """Ten coloured blocks close together on a flat table; the first is the target."""
    color = np.empty((SIZE, SIZE, 3), np.uint8)
    color[:] = (120, 110, 100)
    depth = np.zeros((SIZE, SIZE), np.float32)
    mask = np.zeros((SIZE, SIZE), np.uint8)
    for i in range(blocks):
        h, w = rng.integers(12, 40, size=2)
        r, c = rng.integers(60, 140, size=2)
        color[r : r + h, c : c + w] = rng.integers(0, 255, 3, dtype=np.uint8)
        depth[r : r + h, c : c + w] = np.float32(rng.uniform(0.02, 0.08)) + np.linspace(0, 0.004, w, dtype=np.float32)
        if i == 0:
            mask[r : r + h, c : c + w] = 1
    return {"color": color, "depth": depth, "mask": mask, "occluded": np.zeros(1, np.int8)}


def stage5_stream(steps: int, seed: int = 0) -> tuple[list[tuple[dict, dict, int, float, bool]], str]:
    """``steps`` transitions (obs, next_obs, action, reward, done) from Stage 5, or synthetic ones."""
    try:
        import gymnasium as gym

        import mpg_envs  # noqa: F401  (registers the ids)

        env = gym.make("MPG-Stage5-v0")
        obs, _ = env.reset(seed=seed)
        out = []
        for _ in range(steps):
            action = int(env.action_space.sample())
            nxt, reward, term, trunc, _ = env.step(action)
            out.append((obs, nxt, action, float(reward), bool(term)))
            obs = env.reset()[0] if term or trunc else nxt
        env.close()
        return out, "MPG-Stage5-v0"
    except Exception as exc:  # noqa: BLE001 - fall back to synthetic scenes, say so
        print(f"(MPG-Stage5-v0 unavailable: {exc!r}; using synthetic scenes)")
        rng = np.random.default_rng(seed)
        scenes = [synthetic_scene(rng) for _ in range(steps + 1)]
        return [(scenes[i], scenes[i + 1], 0, 0.0, False) for i in range(steps)], "synthetic"


def interleaved_times(fns: list[Callable[[], Any]], repeats: int, warmup: int = 1) -> list[list[float]]:
    """Wall times of each function over ``repeats`` rounds, the functions run in turn each round.

    The order alternates between rounds: whichever runs second finds the weights warm in the
    CPU caches, which would otherwise favour one function throughout.
    """
    for fn in fns:
        for _ in range(warmup):
            fn()
    times: list[list[float]] = [[] for _ in fns]
    for round_ in range(repeats):
        order = list(range(len(fns)))
        for i in order if round_ % 2 == 0 else order[::-1]:
            start = time.perf_counter()
            fns[i]()
            times[i].append(time.perf_counter() - start)
    return times


def median_times(fns: list[Callable[[], Any]], repeats: int, warmup: int = 1) -> list[float]:
    """Median wall time of each function, running them in turn ``repeats`` times."""
    return [statistics.median(t) for t in interleaved_times(fns, repeats, warmup)]


def convolution_seconds(fn: Callable[[], Any], runs: int = 3) -> float:
    """CPU seconds per call spent inside oneDNN convolutions (torch profiler, self time).

    With 2 threads this is close to wall time; it shows how much of a path is trunk compute
    and how much resampling and per-call overhead.
    """
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(runs):
            fn()
    total = sum(e.self_cpu_time_total for e in prof.key_averages() if "convolution" in e.key)
    return total / runs / 1e6


def sequential_decision(net: MPGNet, obs: dict[str, np.ndarray], q_star: float) -> tuple[str, int]:
    """The workflow's worst case with one rotation per forward pass, VPG's way: the observation
    is normalised once, then each rotation is resampled and run through the mask trunk and both
    branches on its own."""
    grasp, push = [], []
    prepared = net.prepare(obs)
    region = prepared.region
    for k in range(net.config.num_rotations):
        enc = net.encode(prepared, rotations=torch.tensor([k]))
        grasp.append(net.branch_q(enc, "grasp"))
        push.append(net.branch_q(enc, "push"))
    q_grasp = torch.stack(grasp, dim=1)
    score = float(region_max(q_grasp, region)[0])
    q = q_grasp if score >= q_star else torch.stack(push, dim=1)
    return ("grasp" if score >= q_star else "push"), int(q.flatten().argmax())


def _busy_loop(started: Any) -> None:
    started.set()
    while True:
        pass


class BusyLoops:
    """``n`` processes spinning on the CPU (as other users' work would) while the block runs.

    They inherit this process's CPU affinity, so under ``taskset`` they compete for the same
    cores; they are terminated on exit.
    """

    def __init__(self, n: int = 2):
        self.n = n
        self._procs: list[Any] = []

    def __enter__(self) -> "BusyLoops":
        ctx = multiprocessing.get_context("fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn")
        for _ in range(self.n):
            started = ctx.Event()
            proc = ctx.Process(target=_busy_loop, args=(started,), daemon=True)
            proc.start()
            started.wait(60)
            self._procs.append(proc)
        time.sleep(0.5)  # let the scheduler see them as steady CPU hogs
        return self

    def __exit__(self, *exc: object) -> None:
        for proc in self._procs:
            proc.terminate()
        for proc in self._procs:
            proc.join()
        self._procs.clear()


def loaded_decisions(decide: Callable[[], Any], repeats: int, threads: int | None, busy: int = 2) -> tuple[list[float], int]:
    """Wall times of ``decide`` while ``busy`` busy-looping processes run, and the threads used.

    The threads are chosen again once the loops run, as a process started on that busy machine
    would choose them (``threads`` fixes them, as ``--threads`` does for the quiet runs).
    """
    quiet_threads = torch.get_num_threads()
    with BusyLoops(busy):
        used = set_torch_threads(threads)
        decide()  # warm-up at this thread count
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            decide()
            times.append(time.perf_counter() - start)
    torch.set_num_threads(quiet_threads)
    return times, used


def bench_variant(
    variant: str,
    obs: dict[str, np.ndarray],
    repeats: int,
    loaded: bool = False,
    threads: int | None = None,
    busy: int = 2,
) -> dict[str, float]:
    torch.manual_seed(0)
    space = PixelActionSpace(PRIMITIVES)
    # Q*_g = +inf: never graspable, so every decision runs mask + grasp + push (the worst case).
    policy = MPGNetPolicy(observation_space(), space, lambda _: 1e-4, variant=variant, q_star=float("inf"))
    # Trained-like BN statistics: an untrained net in eval mode decays activations into
    # denormal floats, which is not what a trained policy costs.
    recompute_batch_norm_statistics(
        policy.q_net, policy.q_net.q_maps, {k: torch.as_tensor(v)[None] for k, v in obs.items()}
    )
    policy.set_training_mode(False)
    assert policy.decide(obs).primitive == "push"
    net = policy.q_net.mpgnet

    def batched() -> None:
        policy.predict(obs, deterministic=True)

    def sequential() -> None:
        with torch.inference_mode():
            sequential_decision(net, obs, float("inf"))

    # Interleaved so a load spike from other processes hits both paths alike; the speed-up is
    # the median of the per-round ratios, which a spike spanning one round cannot skew.
    batched_t, seq_t = interleaved_times([batched, sequential], repeats)
    decision, seq = statistics.median(batched_t), statistics.median(seq_t)
    speedup = statistics.median(s / b for b, s in zip(batched_t, seq_t, strict=True))
    conv_batched, conv_seq = convolution_seconds(batched), convolution_seconds(sequential)

    # One training step: batch of 4 on the grasp branch.
    batch = {k: torch.as_tensor(np.stack([obs[k]] * 4)) for k in obs}
    actions = torch.tensor([space.encode("grasp", k, 100, 110) for k in (0, 3, 7, 12)])
    targets = torch.ones(4, 1)

    def train_step() -> None:
        policy.set_training_mode(True)
        q = policy.q_net.q_values_at(batch, actions)
        loss = F.smooth_l1_loss(q, targets)
        policy.optimizer.zero_grad()
        loss.backward()
        policy.optimizer.step()

    (train,) = median_times([train_step], max(3, repeats // 2))
    policy.set_training_mode(False)
    extra: dict[str, float] = {}
    if loaded:
        loaded_t, used = loaded_decisions(batched, repeats, threads, busy)
        extra = {
            "loaded_decision_s": statistics.median(loaded_t),
            "loaded_ratio": statistics.median(loaded_t) / decision,
            "loaded_threads": used,
        }
    return {
        **extra,
        "decision_s": decision,
        "sequential_s": seq,
        "speedup": speedup,
        "conv_s": conv_batched,
        "sequential_conv_s": conv_seq,
        "train_step_s": train,
    }


def replay_bytes(stream: list[tuple[dict, dict, int, float, bool]]) -> tuple[float, float]:
    """Bytes per transition of our buffer and of SB3's DictReplayBuffer for the same stream."""
    n = len(stream)
    space = PixelActionSpace(PRIMITIVES)
    ours = PrioritizedHeightmapReplayBuffer(n, observation_space(), space, device="cpu")
    sb3 = DictReplayBuffer(n, observation_space(), space, device="cpu")
    for obs, nxt, action, reward, done in stream:
        args = (
            {k: np.asarray(v)[None] for k, v in obs.items()},
            {k: np.asarray(v)[None] for k, v in nxt.items()},
            np.array([action]),
            np.array([reward], np.float32),
            np.array([done]),
            [{}],
        )
        ours.add(*args)
        sb3.add(*args)
    sb3_total = sb3_dict_buffer_nbytes(sb3)
    return ours.nbytes() / n, sb3_total / n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="timed runs per measurement (median)")
    parser.add_argument("--variants", nargs="+", default=["small", "large"], choices=["small", "large"])
    parser.add_argument("--replay-steps", type=int, default=40)
    parser.add_argument(
        "--threads", type=int, default=None,
        help=f"torch threads (default: chosen from the free cores, or {THREADS_ENV} / OMP_NUM_THREADS)",
    )
    parser.add_argument("--busy", type=int, default=2, help="busy-looping processes for the loaded decision (0: skip it)")
    args = parser.parse_args()
    load_at_start = load_average()
    threads = set_torch_threads(args.threads)
    torch.set_flush_denormal(True)  # belt and braces: denormals cost 10-100x per operation on x86

    stream, source = stage5_stream(args.replay_steps)
    obs = dict(stream[0][0])
    obs["occluded"] = np.zeros(1, np.int8)  # not occluded: the grasp/push path

    load_before = os.getloadavg()[0]
    results = {
        v: bench_variant(
            v, obs, args.repeats if v == "small" else max(3, args.repeats // 2),
            loaded=args.busy > 0 and v == args.variants[0], threads=args.threads, busy=args.busy,
        )
        for v in args.variants
    }
    ours, theirs = replay_bytes(stream)

    print(
        f"MPGNet policy speed, torch {torch.__version__}, {threads} threads (load {load_at_start:.2f} on "
        f"{len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count()} cores at start, "
        f"OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY', '<unset>')}), observations: {source}"
    )
    print(
        f"{'variant':<8} {'decision (s)':>13} {'sequential (s)':>15} {'speed-up':>9} "
        f"{'conv batched/seq (s)':>21} {'train step (s)':>15}"
    )
    for v, r in results.items():
        print(
            f"{v:<8} {r['decision_s']:>13.3f} {r['sequential_s']:>15.3f} {r['speedup']:>8.2f}x "
            f"{r['conv_s']:>10.3f}/{r['sequential_conv_s']:<10.3f} {r['train_step_s']:>15.3f}"
        )
    print("(speed-up: median of per-round ratios; conv: CPU time inside convolutions per decision)")
    for v, r in results.items():
        if "loaded_ratio" in r:
            print(
                f"{v}: decision {r['loaded_decision_s']:.3f} s while {args.busy} busy loops run "
                f"({int(r['loaded_threads'])} threads), {r['loaded_ratio']:.2f}x the quiet decision "
                f"(fair sharing of 2 cores among 3 processes: 1.5-2x)"
            )
    print(
        f"1-min load average {load_before:.2f} before, {os.getloadavg()[0]:.2f} after "
        "(above ~0.5 other processes share the 2 cores and the times are inflated)"
    )
    print(f"replay bytes/transition: ours {ours:,.0f}  SB3 DictReplayBuffer {theirs:,.0f}  ratio {ours / theirs:.4f}")
    summary = {
        "decision_s": {v: round(r["decision_s"], 4) for v, r in results.items()},
        "sequential_s": {v: round(r["sequential_s"], 4) for v, r in results.items()},
        "speedup": {v: round(r["speedup"], 2) for v, r in results.items()},
        "conv_s": {v: round(r["conv_s"], 4) for v, r in results.items()},
        "sequential_conv_s": {v: round(r["sequential_conv_s"], 4) for v, r in results.items()},
        "train_step_s": {v: round(r["train_step_s"], 4) for v, r in results.items()},
        "replay_bytes": round(ours, 1),
        "sb3_replay_bytes": round(theirs, 1),
        "threads": threads,
        "load_at_start": round(load_at_start, 2),
    }
    for v, r in results.items():
        if "loaded_ratio" in r:
            summary.update(
                loaded_variant=v,
                loaded_decision_s=round(r["loaded_decision_s"], 4),
                loaded_ratio=round(r["loaded_ratio"], 2),
                loaded_threads=int(r["loaded_threads"]),
            )
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
