"""Seconds per TD step (``mpg_agents.learning.td_step.td_step``) at given batch sizes, on recorded
Stage V transitions, with the shipped training configuration's network (small; ``[net_config]`` of
``mpg_agents/checkpoints/mpgnet_train.toml``: colour-free, grasp region on the target, 8 px off its
rim, zero-initialised heads) and its Q bounds; ``--net-option KEY=VALUE`` sets an
``MPGNetConfig`` field over it (``color_input=True``: the paper's colour trunks).

First record transitions once (env steps: the heuristic grasp, or a random move/push):

    python benchmarks/td_step_speed.py --record /tmp/stage5_transitions.npz --transitions 24

then time the step (the same file gives the same batches to any version of the code):

    python benchmarks/td_step_speed.py --transitions-file /tmp/stage5_transitions.npz --batch-sizes 2,16 --repeats 5 [--decisions 20]

Each batch holds the first ``B`` transitions; the first repeat of each size is a warm-up (not
counted). The networks start from ``--seed``; every step trains them (Adam), so repeats see
slightly different weights, as training does. ``--device`` puts the networks and the batches
on ``cpu`` or ``cuda`` (where the code has a device option). ``--decisions N`` also times the
full coordinated decision (``agent.decide``, Q*_g 0.6) on the recorded observations.
``--profile`` also splits each batch size's step into its phases (the targets, of which the
all-rotation greedy pass, the training forward, backward and optimizer step; medians, synchronised
on a GPU) and prints ``torch.profiler``'s table of the ops that took the most time over two steps
(kernel time on a GPU), with the number of kernel launches and host synchronisations. The last
output line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from types import SimpleNamespace

import numpy as np
import torch


RATIO_GOAL = 4.0
"""At most this many times batch 2's seconds for a TD step at batch 16: the step's fixed work is
shared by the batch. Met on a GPU (2.2x on an H200); on a CPU the convolutions of the exact
targets' all-rotation greedy pass grow with the batch (7.7x on 2 threads of an AVX-512 Xeon)."""


def shipped_net_config(options: list[str]) -> dict:
    """The shipped training config's ``[net_config]``, with ``KEY=VALUE`` options over it (a
    value read as ``--env-option``'s are: a Python literal, else text).

    Raises:
        ValueError: an option without ``=`` or with a key that is no ``MPGNetConfig`` field.
    """
    from dataclasses import fields

    from mpg_agents.cli_input import read_config
    from mpg_agents.evaluation.env_options import literal_or_text
    from mpg_agents.learning.train_runs import DEFAULT_CONFIG
    from mpg_agents.network.mpgnet_config import MPGNetConfig

    net_config = dict(read_config(str(DEFAULT_CONFIG)).get("net_config", {}))
    known = {f.name for f in fields(MPGNetConfig)}
    for text in options:
        key, sep, value = text.partition("=")
        if not sep or key.strip() not in known:
            raise ValueError(f"--net-option takes KEY=VALUE with KEY an MPGNetConfig field ({', '.join(sorted(known))}), got {text!r}")
        net_config[key.strip()] = literal_or_text(value)
    return net_config


def record(path: str, transitions: int, seed: int) -> None:
    """Step MPG-Stage5-v0 and save ``transitions`` transitions to ``path`` (npz)."""
    import gymnasium as gym

    import mpg_envs  # noqa: F401
    from mpg_envs.policies.pixel_heuristic import heuristic_grasp_action

    env = gym.make("MPG-Stage5-v0")
    space = env.unwrapped.action_space
    rng = np.random.default_rng(seed)
    rows: dict[str, list] = {"actions": [], "rewards": [], "dones": []}
    obs_list, next_list = [], []
    obs, _ = env.reset(seed=seed)
    while len(rows["actions"]) < transitions:
        if rng.random() < 0.5 and obs["mask"].any():
            action = heuristic_grasp_action(obs, space.primitives)
        else:
            prim = str(rng.choice(("move", "push")))
            rows_, cols = np.nonzero(obs["mask"]) if obs["mask"].any() else (np.array([112]), np.array([112]))
            k = int(rng.integers(len(rows_)))
            action = space.encode(prim, int(rng.integers(16)), int(rows_[k]), int(cols[k]))
        next_obs, reward, terminated, truncated, _ = env.step(action)
        obs_list.append(obs)
        next_list.append(next_obs)
        rows["actions"].append(action)
        rows["rewards"].append(reward)
        rows["dones"].append(float(terminated))
        obs = env.reset(seed=seed + len(rows["actions"]))[0] if terminated or truncated else next_obs
    data = {f"obs_{k}": np.stack([o[k] for o in obs_list]) for k in obs_list[0]}
    data.update({f"next_{k}": np.stack([o[k] for o in next_list]) for k in next_list[0]})
    data.update({k: np.asarray(v) for k, v in rows.items()})
    np.savez_compressed(path, **data)
    print(f"recorded {transitions} transitions to {path} ({int(sum(rows['dones']))} terminal)")


def batch_of(data: dict[str, np.ndarray], size: int, device: torch.device) -> SimpleNamespace:
    """The first ``size`` recorded transitions as a replay batch on ``device``."""
    keys = [k[4:] for k in data if k.startswith("obs_")]
    if size > len(data["actions"]):
        raise ValueError(f"batch {size} needs {size} recorded transitions; the file has {len(data['actions'])}")
    return SimpleNamespace(
        observations={k: torch.as_tensor(data[f"obs_{k}"][:size]).to(device) for k in keys},
        next_observations={k: torch.as_tensor(data[f"next_{k}"][:size]).to(device) for k in keys},
        actions=torch.as_tensor(data["actions"][:size]).reshape(-1, 1).to(device),
        rewards=torch.as_tensor(data["rewards"][:size], dtype=torch.float32).reshape(-1, 1).to(device),
        dones=torch.as_tensor(data["dones"][:size], dtype=torch.float32).reshape(-1, 1).to(device),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--record", help="record transitions to this npz file and stop")
    parser.add_argument("--transitions", type=int, default=24)
    parser.add_argument("--transitions-file", help="the npz file --record wrote")
    parser.add_argument("--batch-sizes", default="2,16")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--profile", action="store_true", help="also time each phase of the step and print torch.profiler's top ops")
    parser.add_argument("--net-option", action="append", default=[], metavar="KEY=VALUE", help="an MPGNetConfig field over the shipped config's")
    parser.add_argument("--decisions", type=int, default=0, help="also time this many coordinated decisions (agent.decide) on the recorded observations")
    args = parser.parse_args()
    if args.record:
        record(args.record, args.transitions, args.seed)
        return
    if not args.transitions_file:
        parser.error("give --transitions-file (written by --record)")
    from mpg_agents.acting.agent import MPGAgent
    from mpg_agents.acting.q_function import MPGQFunction
    from mpg_agents.learning.td_step import TDStepConfig, td_step
    from mpg_envs.grid.actions import PixelActionSpace
    from mpg_envs.tasks.config import observation_space

    torch.set_num_threads(args.threads)
    torch.set_flush_denormal(True)
    device = torch.device(args.device)
    data = dict(np.load(args.transitions_file))
    space = PixelActionSpace(("move", "push", "grasp"))
    torch.manual_seed(args.seed)
    agent = MPGAgent.build(observation_space(), space, variant="small", net_config=shipped_net_config(args.net_option))
    target = MPGQFunction(agent.net_config, agent.action_primitives)
    target.load_state_dict(agent.q_net.state_dict())
    agent.q_net.to(device)
    target.to(device)
    target.set_training_mode(False)
    optimizer = torch.optim.Adam(agent.q_net.parameters(), lr=1e-4, weight_decay=2**-5, betas=(0.9, 0.99))
    config = TDStepConfig(gamma=0.5, target_bounds=(-1.0, 2.0))
    seconds: dict[int, float] = {}
    for size in (int(b) for b in args.batch_sizes.split(",")):
        batch = batch_of(data, size, device)
        times = []
        for _ in range(args.repeats + 1):
            times.append(timed(lambda: td_step(agent.q_net, target, optimizer, batch, config), device)[1])
        seconds[size] = statistics.median(times[1:])
        print(f"batch {size:3d}: {seconds[size]:.3f} s per TD step (median of {args.repeats}; {args.threads} thread(s), {device})")
        if args.profile:
            profile_step(agent.q_net, target, optimizer, batch, config, args.repeats, device)
    sizes = sorted(seconds)
    if len(sizes) >= 2:
        ratio = seconds[sizes[-1]] / seconds[sizes[0]]
        met = "met" if ratio <= RATIO_GOAL else "NOT met"
        print(f"batch {sizes[-1]} / batch {sizes[0]}: {ratio:.1f}x (goal for 16 / 2: at most {RATIO_GOAL:g}x; {met})")
    result = {"td_step_s": {str(k): round(v, 4) for k, v in seconds.items()}, "device": str(device), "threads": args.threads,
              "net_config": {k: v for k, v in agent.net_config.to_dict().items() if k in ("color_input", "channels_last", "trunk_batch")}}
    if args.decisions:
        result["decision_s"] = round(time_decisions(agent, data, args.decisions, device), 4)
        print(f"decision: {result['decision_s']:.3f} s (median of {args.decisions}; the full coordinated decision, {device})")
    print(json.dumps(result))


def timed(fn, device: torch.device):
    """``(fn(), seconds)``, synchronised before and after on a GPU (its work is asynchronous)."""
    if device.type == "cuda":
        torch.cuda.synchronize()
    start = time.perf_counter()
    out = fn()
    if device.type == "cuda":
        torch.cuda.synchronize()
    return out, time.perf_counter() - start


def profile_step(q_net, target, optimizer, batch, config, repeats: int, device: torch.device) -> None:
    """Print the median seconds of each phase of a TD step on ``batch`` and the profiler's top ops."""
    from torch.nn import functional as F

    from mpg_agents.learning.td_step import td_step, td_targets

    phases: dict[str, list[float]] = {"targets": [], "greedy pass": [], "forward": [], "backward": [], "optimizer": []}
    actions = batch.actions.reshape(-1).long()
    for _ in range(repeats):
        with torch.no_grad():
            q_net.set_training_mode(False)
            phases["greedy pass"].append(timed(lambda: q_net.greedy_actions(batch.next_observations), device)[1])
        q_net.set_training_mode(True)
        ys, t = timed(lambda: td_targets(q_net, target, batch.next_observations, batch.rewards, batch.dones, config.gamma, config.target_bounds), device)
        phases["targets"].append(t)
        loss, t = timed(lambda: F.smooth_l1_loss(q_net.q_values_at(batch.observations, actions), ys), device)
        phases["forward"].append(t)
        optimizer.zero_grad(set_to_none=True)
        phases["backward"].append(timed(loss.backward, device)[1])
        phases["optimizer"].append(timed(optimizer.step, device)[1])
    print("  phases (median s): " + ", ".join(f"{k} {statistics.median(v):.4f}" for k, v in phases.items()) + " (the greedy pass is part of the targets)")
    activities = [torch.profiler.ProfilerActivity.CPU] + ([torch.profiler.ProfilerActivity.CUDA] if device.type == "cuda" else [])
    with torch.profiler.profile(activities=activities) as prof:
        for _ in range(2):
            td_step(q_net, target, optimizer, batch, config)
        if device.type == "cuda":
            torch.cuda.synchronize()
    events = prof.key_averages()
    if device.type == "cuda":
        launches = sum(e.count for e in events if e.key in ("cudaLaunchKernel", "cuLaunchKernel"))
        syncs = sum(e.count for e in events if e.key in ("cudaStreamSynchronize", "cudaDeviceSynchronize"))
        kernel_s = sum(e.self_device_time_total for e in events) / 2e6
        print(f"  per step: {kernel_s:.4f} s of GPU kernels, {launches // 2} kernel launches, {syncs // 2} host synchronisations")
    print(events.table(sort_by="self_cuda_time_total" if device.type == "cuda" else "self_cpu_time_total", row_limit=15, max_name_column_width=50))


def time_decisions(agent, data: dict[str, np.ndarray], count: int, device: torch.device) -> float:
    """Median seconds of one coordinated decision (``agent.decide``) over the recorded observations, after a warm-up."""
    keys = [k[4:] for k in data if k.startswith("obs_")]
    agent.to(device)
    agent.set_q_star(0.6)  # a calibrated threshold, so the workflow runs the grasp, mask and push nets as it does when acting
    times = []
    for i in range(count + 1):
        obs = {k: data[f"obs_{k}"][i % len(data["actions"])] for k in keys}
        times.append(timed(lambda: agent.decide(obs), device)[1])
    return statistics.median(times[1:])


if __name__ == "__main__":
    main()
