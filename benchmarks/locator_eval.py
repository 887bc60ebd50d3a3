"""Held-out figures of a target locator on the benchmark's exemplar tracks, by visibility band.

For each track and object count, episodes of the track's held-out test scenes (seeds from
``--seed``, 500000 on) are reset and disturbed by a few moves and pushes at objects, half of
them over the target's footprint (:func:`mpg_agents.locator.samples.episode_samples`, the same
recipe the locator trains on, here on test scenes it never saw); every state is located and
compared with the simulator's top-surface pixels. Prints, per cell and pooled, the samples,
mean IoU and how often "seen" was claimed in each visibility band (the hidden band's is the
false-claim rate), and the locator's median seconds per decision; writes them as JSON.

``--hidden`` measures the false claims alone, on many more hidden states than the disturbing
motions leave: each seed's scene is drawn with the target fully hidden at the reset (the env's
``visible_range=(0, 0)``, up to ``--scene-tries`` draws of a scene, the track's other settings
kept), only that state is located, and seeds where no such scene comes are skipped and counted.
The false-claim rate gets a 95% Wilson interval.

Usage::

    MUJOCO_GL=egl python benchmarks/locator_eval.py --locator runs/locator/locator.safetensors \\
        --tracks MPG-OccludedHardExemplar-v0 MPG-OccludedHardNovelExemplar-v0 MPG-OccludedHardCameraExemplar-v0 \\
        --objects 15 30 --episodes 40 --seed 500000 --json benchmarks/results/locator/heldout.json
    python benchmarks/locator_eval.py --locator runs/locator/locator.safetensors --hidden \
        --objects 30 --episodes 60 --seed 500000 --json hidden.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import torch

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_agents.evaluation.stats import wilson_interval
from mpg_agents.locator.locator import SHIPPED_LOCATOR, TargetLocator
from mpg_agents.locator.metrics import locator_figures
from mpg_agents.locator.run import write_locator
from mpg_agents.locator.samples import SampleSource, episode_samples, sample_observation
from mpg_envs.files import write_text_whole
from mpg_envs.scenes.generators import InvalidSceneError
from mpg_envs.tasks.tracks import TRACKS

HIDDEN_SCENE_TRIES = 100
"""Scene draws per seed allowed by ``--hidden`` (a fully hidden target is rarer than a buried one)."""


def hidden_env(track: str, num_objects: int, scene_tries: int) -> gym.Env:
    """``track``'s env whose resets hide the target fully (its other settings kept)."""
    config = {**TRACKS[track].options.get("config", {}), "scene_tries": scene_tries}
    return gym.make(track, num_objects=num_objects, visible_range=(0.0, 0.0), config=config)


def hidden_claims(locator: TargetLocator, env: gym.Env, seeds: range, seconds: list[float]) -> dict[str, float]:
    """How often ``locator`` claims to see the target in the reset states of ``env``'s ``seeds``
    (each hides it fully), with a 95% Wilson interval; seeds without a valid scene are counted."""
    claims = states = skipped = 0
    for seed in seeds:
        try:
            obs, info = env.reset(seed=seed)
        except InvalidSceneError:
            skipped += 1
            continue
        if float(info["visible_fraction"]) > 0.0:
            shown = info["visible_fraction"]
            raise RuntimeError(f"seed {seed}: the reset's target shows ({shown}); visible_range was not kept")
        started = time.perf_counter()
        claims += bool(locator.locate(obs).seen)
        seconds.append(time.perf_counter() - started)
        states += 1
    return {**claim_figures(claims, states), "seeds_without_scene": float(skipped)}


def claim_figures(claims: int, states: int) -> dict[str, Any]:
    """``claims`` "seen" of ``states`` hidden-target states: the counts, the rate and its 95%
    Wilson interval (NaN without a state)."""
    nan = float("nan")
    return {
        "hidden_states": float(states),
        "false_claims": float(claims),
        "false_claim_rate": claims / states if states else nan,
        "interval_95": list(wilson_interval(claims, states)) if states else [nan, nan],
    }


def hidden_report(locator: TargetLocator, args: argparse.Namespace, report: dict[str, Any], seconds: list[float]) -> None:
    """``--hidden``: each cell's false claims, and pooled, into ``report``."""
    report["hidden"] = True
    for track in args.tracks:
        for n in args.objects:
            env = hidden_env(track, n, args.scene_tries)
            try:
                figures = hidden_claims(locator, env, range(args.seed, args.seed + args.episodes), seconds)
            finally:
                env.close()
            report["cells"][f"{track} {n}"] = figures
            print(f"{track}, {n} objects, target hidden: {json.dumps(figures)}", flush=True)
    cells = report["cells"].values()
    report["pooled"] = claim_figures(int(sum(c["false_claims"] for c in cells)), int(sum(c["hidden_states"] for c in cells)))


def band_report(locator: TargetLocator, args: argparse.Namespace, report: dict[str, Any], seconds: list[float]) -> None:
    """Each cell's IoU and "seen" claims by visibility band, and pooled, into ``report``."""
    pooled: dict[str, list] = {"masks": [], "seen": [], "labels": [], "visible": []}
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--locator", default=str(SHIPPED_LOCATOR), help="weights file (default: the shipped locator)")
    parser.add_argument("--tracks", nargs="+", default=["MPG-OccludedHardExemplar-v0"])
    parser.add_argument("--objects", nargs="+", type=int, default=[15])
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--motions", type=int, default=4, help="disturbing motions after each reset")
    parser.add_argument("--seed", type=int, default=500000)
    parser.add_argument("--json", type=Path)
    parser.add_argument("--torch-threads", type=int, default=1, help="torch threads per decision (2: a 2-core machine's own)")
    parser.add_argument("--hidden", action="store_true", help="false claims on resets that hide the target fully")
    parser.add_argument("--scene-tries", type=int, default=HIDDEN_SCENE_TRIES, help="with --hidden: scene draws per seed")
    parser.add_argument(
        "--record",
        action="store_true",
        help="also keep the figures in the locator's training record and write its model card again "
        "(after every choice is made: never choose by held-out figures)",
    )
    args = parser.parse_args()
    torch.set_num_threads(args.torch_threads)
    locator = TargetLocator.load(args.locator)
    report: dict = {
        "locator": args.locator,
        "seed": args.seed,
        "episodes": args.episodes,
        "motions": args.motions,
        "torch_threads": args.torch_threads,
        "mujoco": mujoco.__version__,
        "cells": {},
    }
    seconds: list[float] = []
    (hidden_report if args.hidden else band_report)(locator, args, report, seconds)
    report["median_decision_s"] = statistics.median(seconds) if seconds else float("nan")
    print(f"pooled: {json.dumps(report['pooled'])}")
    print(f"median seconds per locator decision ({args.torch_threads} torch threads): {report['median_decision_s']:.4f}")
    if args.json is not None:
        write_text_whole(args.json, json.dumps(report, indent=2) + "\n")
    if args.record:
        if args.hidden:
            locator.record["heldout_hidden"] = report
        else:
            locator.record["heldout"] = {**report, "cells": list(report["cells"])}
        card = write_locator(locator, Path(args.locator))
        print(f"kept the figures in {args.locator} and wrote {card}")


if __name__ == "__main__":
    main()
