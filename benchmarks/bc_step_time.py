"""Seconds per behaviour-cloning gradient step by rotations per sample, in one run on one machine.

    python benchmarks/bc_step_time.py --demos DIR [--rotations 16 4 2] [--steps 4] [--batch-size 4]

Draws batches from the dataset ``DIR`` (``mpg-demos``), and for each number of rotations per
sample runs ``--steps`` gradient steps of the behaviour-cloning loss (the exact one at 16, the
sampled softmax below it; :func:`mpg_agents.imitation.bc_training.step_logits`) on one net, and
prints each step's seconds and the median of all but the first (warm-up). It first checks that
the sampled path with every rotation listed gives the exact loss. Threads: ``MPG_NUM_THREADS`` or
the cores free now, as ``mpg-train``. Say the machine and its load with the figures.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np
import torch

from mpg_agents.imitation.bc_config import BCConfig, bc_net_config
from mpg_agents.imitation.bc_loss import imitation_loss, sampled_rotations
from mpg_agents.imitation.bc_training import step_logits
from mpg_agents.imitation.demo_samples import DemoSamples
from mpg_agents.network.mpgnet import MPGNet, flat_q
from mpg_envs.threads import set_torch_threads


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--demos", required=True, help="a dataset folder of mpg-demos")
    parser.add_argument("--rotations", type=int, nargs="+", default=[16, 4, 2])
    parser.add_argument("--steps", type=int, default=4)
    parser.add_argument("--batch-size", type=int, default=4)
    args = parser.parse_args(argv)
    set_torch_threads()
    samples = DemoSamples(args.demos)
    primitives = samples.action_primitives
    print(
        f"{len(samples)} samples of {samples.source.env_id} ({', '.join(primitives)}); batch {args.batch_size}; "
        f"{torch.get_num_threads()} torch threads; load average {os.getloadavg()[0]:.2f}"
    )
    torch.manual_seed(0)
    net = MPGNet(bc_net_config(BCConfig(), primitives))
    for p in net.parameters():  # a head that is not zero, so the check below compares different logits
        p.data.add_(0.01 * torch.randn_like(p))
    net.train()
    rng = np.random.default_rng(0)
    obs, actions = samples.batch(np.arange(min(2, len(samples))))
    batch = {k: torch.from_numpy(v) for k, v in obs.items()}
    with torch.no_grad():
        exact = imitation_loss(flat_q(net(batch, primitives), primitives), torch.from_numpy(actions))
        r, size = net.config.num_rotations, net.config.heightmap_size
        rotations, classes = sampled_rotations(rng, actions, r, r, size * size)
        maps = net.maps_from(net.encode(batch, rotations=torch.from_numpy(rotations)), primitives)
        listed = imitation_loss(flat_q(maps, primitives), torch.from_numpy(classes))
    print(f"check: exact loss {float(exact):.5f}, every rotation listed {float(listed):.5f}")
    optimizer = torch.optim.Adam(net.parameters(), lr=1e-3)
    for k in args.rotations:
        config = BCConfig(rotations_per_sample=k, batch_size=args.batch_size)
        seconds = []
        for _ in range(args.steps):
            obs, actions = samples.batch(rng.choice(len(samples), args.batch_size, replace=len(samples) < args.batch_size))
            batch = {key: torch.from_numpy(v) for key, v in obs.items()}
            start = time.perf_counter()
            logits, target = step_logits(net, batch, actions, primitives, config, rng)
            loss = imitation_loss(logits, target)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            seconds.append(time.perf_counter() - start)
        later = seconds[1:] or seconds
        each = ", ".join(f"{s:.2f}" for s in seconds)
        print(f"{k:2d} rotations per sample: {each} s; median after the first {statistics.median(later):.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
