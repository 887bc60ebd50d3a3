"""``mpg-train-locator``: collect samples, train, calibrate and write the locator with its model card.

One command does it all and resumes where it stopped (shards already collected are kept,
training resumes from its last checkpoint)::

    mpg-train-locator --out runs/locator --seed 1 --workers 2

writes ``OUT/locator.safetensors`` (:mod:`mpg_agents.locator.locator`), ``OUT/locator.md`` (the
model card) and ``OUT/figures.json`` (the tuning figures by visibility band). Samples come
from the run's own seeds on the training families and the blocks
(:mod:`mpg_agents.locator.samples`); the "seen" threshold is calibrated on samples of tuning
seeds (700000-), so that "seen" is claimed for at most :data:`FALSE_CLAIMS` of the tuning
samples whose target is hidden.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from mpg_agents.locator.locator import TargetLocator
from mpg_agents.locator.metrics import locator_figures
from mpg_agents.locator.net import LocatorNet
from mpg_agents.locator.samples import SOURCES, collect_shard, read_shards, sample_observation, shard_plan
from mpg_agents.locator.training import TrainSettings, train_locator
from mpg_envs.files import write_text_whole

FALSE_CLAIMS = 0.02
"""The share of hidden-target tuning samples "seen" may be claimed for."""
PIXEL_THRESHOLD = 0.5
"""A pixel is the target's when its probability is at least this."""
SET_SEEDS = 10
"""Shards draw the procedural families with set seeds 1..SET_SEEDS (training shards) or
101..100+SET_SEEDS (tuning shards), in turn."""


def _collect(job: tuple[str, int, str, list[int], int]) -> str:
    """Worker: one shard (``folder, shard, source name, seeds, set seed``), one thread."""
    torch.set_num_threads(1)
    folder, shard, name, seeds, set_seed = job
    source = next(s for s in SOURCES if s.name == name)
    started = time.perf_counter()
    path = collect_shard(Path(folder), shard, source, seeds, set_seed)
    skipped = np.load(path)["skipped_seeds"].tolist()
    note = f", seeds without a valid scene: {skipped}" if skipped else ""
    return f"{path.name} ({name}, {len(seeds)} episodes{note}) in {time.perf_counter() - started:.0f} s"


def collect(folder: Path, shards: int, episodes: int, seed: int, tuning: bool, workers: int, log) -> list[Path]:
    """Every shard of the plan in ``folder`` (the missing ones collected over ``workers`` processes)."""
    folder.mkdir(parents=True, exist_ok=True)
    plan = shard_plan(shards, episodes, seed, tuning=tuning)
    base = 101 if tuning else 1
    jobs = [
        (str(folder), i, source.name, seeds, base + i % SET_SEEDS)
        for i, source, seeds in plan
        if not (folder / f"shard_{i:04d}.npz").is_file()
    ]
    log(f"{folder}: {len(plan) - len(jobs)} of {len(plan)} shards there, collecting {len(jobs)}")
    if jobs:
        with multiprocessing.get_context("spawn").Pool(workers) as pool:
            for line in pool.imap_unordered(_collect, jobs):
                log(line)
    return [folder / f"shard_{i:04d}.npz" for i, _, _ in plan]


def predictions(locator: TargetLocator, data: dict[str, np.ndarray]) -> tuple[list[np.ndarray], list[float]]:
    """The locator's probability maps and seen probabilities on ``data``'s samples."""
    maps, seen = [], []
    for i in range(len(data["label"])):
        location = locator.locate(sample_observation({key: array[i] for key, array in data.items()}))
        maps.append(location.probability)
        seen.append(location.seen_probability)
    return maps, seen


def calibrate_seen(seen: Sequence[float], visible: Sequence[float], false_claims: float = FALSE_CLAIMS) -> float:
    """The lowest "seen" threshold (at least 0.5) that claims at most ``false_claims`` of the
    hidden samples (``visible`` exactly 0); 0.5 when there are none."""
    hidden = np.sort([s for s, v in zip(seen, visible) if v == 0.0])
    if len(hidden) == 0:
        return 0.5
    allowed = int(np.floor(false_claims * len(hidden)))  # claims allowed
    threshold = hidden[len(hidden) - allowed - 1] + 1e-6  # above every hidden sample but the `allowed` highest
    return float(max(0.5, threshold))


def _band_rows(figures: dict[str, Any]) -> str:
    return "\n".join(
        f"| {band} | {int(f['samples'])} | {f['iou']:.3f} | {f['seen_rate']:.1%} |"
        if "iou" in f
        else f"| {band} | {int(f['samples'])} | - | {f['seen_rate']:.1%} (false claims) |"
        for band, f in figures.items()
    )


def _note(record: dict[str, Any]) -> str:
    """The record's ``collect_note`` (what the collection time leaves out, say), in brackets."""
    return f" ({record['collect_note']})" if record.get("collect_note") else ""


def model_card(
    record: dict[str, Any],
    rule: dict[str, Any] | None = None,
    snap: str = "off",
    pose_floor: float | None = None,
    min_fit: float | None = None,
    grow: str = "rated",
) -> str:
    """The model card's Markdown, from the training record (and, once chosen, the search
    ``rule``, the ``snap`` with its settings and the held-out figures the record then holds)."""
    card = f"""# Target locator (`locator.safetensors`)

Finds the exemplar's object in the colour and depth heightmaps: a per-pixel probability that
the pixel shows it (its top surface) and whether it shows at all. The network is
`mpg_agents.locator.net.LocatorNet` ({record["parameters"]:,} parameters); besides the images it
reads the exemplar matcher's colour-and-shape cues (`mpg_agents.locator.features.match_cues`).

## Training
- Command: `{record["command"]}`
- Data: {record["train_samples"]} samples from {record["train_shards"]} shards of the run's own
  seeds (run seed {record["seed"]}): stage 4 and 5 scenes and the hard track's, ray-cast and
  through the cameras, with visual randomization, on the blocks and the procedural training
  families (`mpg_agents.locator.samples.SOURCES`); labels from the simulator (the pixels where
  the target is the top surface). No test seed, no unseen-shape test object.
- {record["steps"]} steps of batch {record["batch_size"]} (AdamW, warm-up then cosine decay from learning rate
  {record["learning_rate"]}), {record["train_seconds"] / 60:.0f} minutes of training on
  {record["machine"]}; collecting the samples took {record["collect_seconds"] / 60:.0f} minutes{_note(record)}.
- Thresholds: a pixel is the target's at probability {record["threshold"]}; "seen" is claimed at
  {record["seen_threshold"]:.3f}, calibrated on {record["tuning_samples"]} tuning samples
  (seeds 700000-) to claim at most {FALSE_CLAIMS:.0%} of hidden targets.

## Tuning figures (seeds 700000-, the training recipe's scenes)

| target visible | samples | IoU | "seen" claimed |
|---|---:|---:|---:|
{_band_rows(record["tuning_figures"])}
"""
    tuning = record.get("rule_tuning")
    floor_note = ""
    if snap == "pose" and pose_floor is not None:
        floor_note = f" (least pose fit {pose_floor})"
    elif snap == "template" and min_fit is not None:
        floor_note = f" (least template fit {min_fit}, `mpg_agents.locator.template.fit_template`; growth `{grow}`)"
    if rule is not None and tuning is not None:
        card += f"""
## Cover and search rule

`{json.dumps(rule)}` (`mpg_agents.locator.cover.CoverRule`), masks snapping
`{snap}`{floor_note} (`mpg_agents.locator.locator.SNAPS`), chosen among
{len(tuning["rules"])} candidates on {tuning["episodes"]} tuning episodes per object count
({", ".join(str(n) for n in tuning["objects"])} objects) of `{tuning["env"]}`, seeds {tuning["seed"]} on, by
`benchmarks/locator_search_tuning.py`.
"""
        snaps = record.get("snap_tuning")
        if snaps is not None:
            card += f"""The snapping was then tried among {", ".join(f"`{c}`" for c in snaps["candidates"])} on
{snaps["episodes"]} other tuning episodes per object count, seeds {snaps["seed"]} on: {snaps["result"]}.
"""
        template = record.get("template_tuning")
        if template is not None:
            card += f"""Then {", ".join(f"`{c}`" for c in template["candidates"])} were played on {template["episodes"]}
tuning episodes, seeds {template["seed"]} on: {template["result"]}.
"""
        misfit = record.get("misfit_tuning")
        if misfit is not None:
            card += f"""The rule's `misfit_motions` (decisions per episode a located object fitting the exemplar
worse than the least template fit is taken as covered) was then chosen among
{", ".join(str(c) for c in misfit["candidates"])} on {misfit["episodes"]} tuning episodes, seeds {misfit["seed"]} on:
{misfit["result"]}.
"""
        growth = record.get("growth_tuning")
        if growth is not None:
            card += f"""How the chosen blob grows over its object (`mpg_agents.locator.locator.GROWTHS`) was then chosen
among {", ".join(f"`{c}`" for c in growth["candidates"])} on {growth["episodes"]} tuning episodes, seeds {growth["seed"]} on:
{growth["result"]}.
"""
    heldout = record.get("heldout")
    if heldout is not None:
        card += f"""
## Held-out figures (the exemplar tracks' test scenes, seeds {heldout["seed"]} on)

{heldout["episodes"]} episodes per cell ({", ".join(heldout["cells"])}), each state after the reset and
{heldout["motions"]} disturbing motions located; `benchmarks/locator_eval.py`. Median
{1000 * heldout["median_decision_s"]:.1f} ms per decision on one thread.

| target visible | samples | IoU | "seen" claimed |
|---|---:|---:|---:|
{_band_rows(heldout["pooled"])}
"""
    else:
        card += "\nHeld-out figures on the benchmark's exemplar tracks: `benchmarks/locator_eval.py`.\n"
    hidden = record.get("heldout_hidden")
    if hidden is not None:
        rows = "\n".join(
            f"| {cell} | {c['hidden_states']:.0f} | {c['false_claims']:.0f} | {c['false_claim_rate']:.1%} "
            f"[{c['interval_95'][0]:.1%}, {c['interval_95'][1]:.1%}] |"
            for cell, c in hidden["cells"].items()
        )
        card += f"""
Targets fully hidden at the reset (`benchmarks/locator_eval.py --hidden`: each seed's scene drawn
with the target's visible fraction 0, seeds {hidden["seed"]} on, the reset's state located):

| cell | hidden states | "seen" claimed | rate [95%] |
|---|---:|---:|---:|
{rows}
"""
        notes = [f"{cell}: {c['stopped']}." for cell, c in hidden["cells"].items() if c.get("stopped")]
        card += "".join(f"\n{note}\n" for note in notes)
    return card


def write_locator(locator: TargetLocator, path: Path) -> Path:
    """Write ``locator`` to ``path`` and its model card beside it (``path`` with ``.md``), each
    whole or not at all; returns the card's path."""
    locator.save(path)
    card = path.with_suffix(".md")
    write_text_whole(
        card,
        model_card(locator.record, locator.rule.to_dict(), locator.snap, locator.pose_floor, locator.min_fit, locator.grow),
    )
    return card


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="mpg-train-locator", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, type=Path, help="run folder (resumes when it holds an earlier run)")
    parser.add_argument("--seed", type=int, default=1, help="run seed: the sample episodes' seeds and the batches' order")
    parser.add_argument("--shards", type=int, default=80, help="training shards")
    parser.add_argument("--tuning-shards", type=int, default=10, help="tuning shards (seeds 700000-)")
    parser.add_argument("--episodes-per-shard", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2, help="processes collecting samples")
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--batch-size", type=int, default=16)
    parser.add_argument("--learning-rate", type=float, default=1e-3)
    parser.add_argument("--torch-threads", type=int, default=2)
    args = parser.parse_args(argv)
    for name in ("shards", "tuning_shards", "episodes_per_shard", "workers", "steps", "batch_size", "torch_threads"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be a positive integer, got {getattr(args, name)}")
    args.out.mkdir(parents=True, exist_ok=True)
    log_file = (args.out / "log.txt").open("a")

    def log(line: str) -> None:
        stamped = f"{time.strftime('%H:%M:%S')} {line}"
        print(stamped, flush=True)
        log_file.write(stamped + "\n")
        log_file.flush()

    timing_path = args.out / "collect_seconds.json"  # collection may span sittings: the card gives the sum
    earlier = json.loads(timing_path.read_text())["seconds"] if timing_path.is_file() else 0.0
    started = time.perf_counter()
    train = collect(args.out / "samples", args.shards, args.episodes_per_shard, args.seed, False, args.workers, log)
    tuning = collect(args.out / "tuning", args.tuning_shards, args.episodes_per_shard, args.seed, True, args.workers, log)
    collect_seconds = earlier + time.perf_counter() - started
    timing_path.write_text(json.dumps({"seconds": collect_seconds}) + "\n")
    torch.set_num_threads(args.torch_threads)
    torch.manual_seed(args.seed)
    data = read_shards(train)
    train_samples = len(data["label"])
    log(f"{train_samples} training samples")
    settings = TrainSettings(args.steps, args.batch_size, args.learning_rate, seed=args.seed)
    net = LocatorNet()
    trained = train_locator(net, data, settings, args.out, log)
    del data
    tuning_data = read_shards(tuning)
    locator = TargetLocator(net, PIXEL_THRESHOLD, 0.5)
    maps, seen = predictions(locator, tuning_data)
    visible = [float(v) for v in tuning_data["visible_fraction"]]
    seen_threshold = calibrate_seen(seen, visible)
    masks = [(m >= PIXEL_THRESHOLD) & (s >= seen_threshold) for m, s in zip(maps, seen)]
    figures = locator_figures(masks, [s >= seen_threshold for s in seen], list(tuning_data["label"]), visible)
    record = {
        "command": "mpg-train-locator " + " ".join(sys.argv[1:] if argv is None else argv),
        "seed": args.seed,
        "train_shards": len(train),
        "train_samples": train_samples,
        "tuning_samples": len(visible),
        "steps": trained["steps"],
        "batch_size": args.batch_size,
        "learning_rate": args.learning_rate,
        "train_seconds": round(trained["seconds"], 1),
        "collect_seconds": round(collect_seconds, 1),
        "machine": f"{os.cpu_count()} CPU cores, {args.torch_threads} torch threads",
        "threshold": PIXEL_THRESHOLD,
        "seen_threshold": seen_threshold,
        "parameters": sum(p.numel() for p in net.parameters()),
        "tuning_figures": figures,
        "settings": asdict(settings),
    }
    write_locator(TargetLocator(net, PIXEL_THRESHOLD, seen_threshold, record), args.out / "locator.safetensors")
    (args.out / "figures.json").write_text(json.dumps(record, indent=2) + "\n")
    log(f"written {args.out / 'locator.safetensors'}; tuning figures {json.dumps(figures)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
