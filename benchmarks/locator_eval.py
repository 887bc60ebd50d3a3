"""Held-out figures of a target locator on the benchmark's exemplar tracks, by visibility band.

For each track and object count, episodes of the track's held-out test scenes (seeds from
``--seed``, 500000 on) are reset and disturbed by a few moves and pushes at objects, half of
them over the target's footprint (:func:`mpg_agents.locator.samples.episode_samples`, the same
recipe the locator trains on, here on test scenes it never saw); every state is located and
compared with the simulator's top-surface pixels. Prints, per cell and pooled, the samples,
mean IoU and how often "seen" was claimed in each visibility band (the hidden band's is the
false-claim rate), and the locator's median seconds per decision; writes them as JSON.

Usage::

    MUJOCO_GL=egl python benchmarks/locator_eval.py --locator runs/locator/locator.safetensors \\
        --tracks MPG-OccludedHardExemplar-v0 MPG-OccludedHardNovelExemplar-v0 MPG-OccludedHardCameraExemplar-v0 \\
        --objects 15 30 --episodes 40 --seed 500000 --json benchmarks/results/locator/heldout.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import gymnasium as gym
import torch

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_agents.locator.locator import SHIPPED_LOCATOR, TargetLocator
from mpg_agents.locator.metrics import locator_figures
from mpg_agents.locator.run import write_locator
from mpg_agents.locator.samples import SampleSource, episode_samples, sample_observation
from mpg_envs.files import write_text_whole


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--locator", default=str(SHIPPED_LOCATOR), help="weights file (default: the shipped locator)")
    parser.add_argument("--tracks", nargs="+", default=["MPG-OccludedHardExemplar-v0"])
    parser.add_argument("--objects", nargs="+", type=int, default=[15])
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--motions", type=int, default=4, help="disturbing motions after each reset")
    parser.add_argument("--seed", type=int, default=500000)
    parser.add_argument("--json", type=Path)
    parser.add_argument(
        "--record",
        action="store_true",
        help="also keep the figures in the locator's training record and write its model card again "
        "(after every choice is made: never choose by held-out figures)",
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    locator = TargetLocator.load(args.locator)
    report: dict = {
        "locator": args.locator,
        "seed": args.seed,
        "episodes": args.episodes,
        "motions": args.motions,
        "cells": {},
    }
    pooled: dict[str, list] = {"masks": [], "seen": [], "labels": [], "visible": []}
    seconds: list[float] = []
    for track in args.tracks:
        for n in args.objects:
            env = gym.make(track, num_objects=n)
            source = SampleSource(track, track, (n,), args.motions, 1.0)
            masks, seen, labels, visible = [], [], [], []
            try:
                for seed in range(args.seed, args.seed + args.episodes):
                    for sample in episode_samples(env, source, seed):
                        obs = sample_observation(sample)
                        started = time.perf_counter()
                        location = locator.locate(obs)
                        seconds.append(time.perf_counter() - started)
                        masks.append(location.mask)
                        seen.append(location.seen)
                        labels.append(sample["label"])
                        visible.append(float(sample["visible_fraction"]))
            finally:
                env.close()
            figures = locator_figures(masks, seen, labels, visible)
            report["cells"][f"{track} {n}"] = figures
            print(f"{track}, {n} objects: {json.dumps(figures)}", flush=True)
            for key, values in zip(("masks", "seen", "labels", "visible"), (masks, seen, labels, visible)):
                pooled[key].extend(values)
    report["pooled"] = locator_figures(pooled["masks"], pooled["seen"], pooled["labels"], pooled["visible"])
    report["median_decision_s"] = statistics.median(seconds)
    print(f"pooled: {json.dumps(report['pooled'])}")
    print(f"median seconds per locator decision (one thread): {report['median_decision_s']:.4f}")
    if args.json is not None:
        write_text_whole(args.json, json.dumps(report, indent=2) + "\n")
    if args.record:
        locator.record["heldout"] = {**report, "cells": list(report["cells"])}
        card = write_locator(locator, Path(args.locator))
        print(f"kept the figures in {args.locator} and wrote {card}")


if __name__ == "__main__":
    main()
