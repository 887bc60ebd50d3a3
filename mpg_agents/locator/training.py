"""Training the locator: batches from sample shards, the loss, and a resumable loop.

The loss (:func:`locator_loss`) is per-pixel binary cross-entropy (targets are small: the
positive pixels weigh :data:`POSITIVE_WEIGHT` times more) plus a soft Dice term on samples
where the target shows, plus binary cross-entropy of the "seen" logit against whether at
least :data:`SEEN_MIN_PIXELS` of the target show. Batches are augmented by the heightmap's
symmetries (quarter turns and mirror images of scene and exemplar, drawn apart): a top-down
view has no preferred direction.
"""

from __future__ import annotations

import csv
import json
import math
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from mpg_agents.locator.features import net_inputs
from mpg_agents.locator.net import LocatorNet
from mpg_agents.locator.samples import sample_observation

POSITIVE_WEIGHT = 4.0
"""Weight of a target pixel in the per-pixel cross-entropy (a target covers a few % of the map)."""
SEEN_MIN_PIXELS = 10
"""A target with at least this many top-surface pixels counts as seen (4 mm^2 per pixel)."""


@dataclass(frozen=True)
class TrainSettings:
    """The loop's settings (the run's seed orders the batches and the augmentation)."""

    steps: int = 2000
    batch_size: int = 16
    learning_rate: float = 1e-3
    weight_decay: float = 1e-5
    checkpoint_every: int = 200
    seed: int = 1


def learning_rate_factor(step: int, steps: int, warmup: float = 0.05) -> float:
    """The learning rate's factor at ``step`` of ``steps``: a linear warm-up over the first
    ``warmup`` share of the steps, then a cosine decay to 0."""
    warm = max(1, round(warmup * steps))
    if step < warm:
        return (step + 1) / warm
    return 0.5 * (1.0 + math.cos(math.pi * (step - warm) / max(1, steps - warm)))


def locator_loss(
    pixel_logits: torch.Tensor, seen_logits: torch.Tensor, labels: torch.Tensor
) -> tuple[torch.Tensor, dict[str, float]]:
    """The loss of a batch (``labels``: B x H x W of 0/1) and its parts by name."""
    labels = labels.float()
    weight = 1.0 + (POSITIVE_WEIGHT - 1.0) * labels
    pixel = F.binary_cross_entropy_with_logits(pixel_logits, labels, weight=weight)
    shows = labels.sum(dim=(1, 2)) >= SEEN_MIN_PIXELS
    dice = pixel_logits.new_zeros(())
    if shows.any():
        prob = torch.sigmoid(pixel_logits[shows])
        target = labels[shows]
        overlap = (prob * target).sum(dim=(1, 2))
        dice = (1.0 - (2.0 * overlap + 1.0) / (prob.sum(dim=(1, 2)) + target.sum(dim=(1, 2)) + 1.0)).mean()
    seen = F.binary_cross_entropy_with_logits(seen_logits, shows.float())
    total = pixel + dice + seen
    return total, {"pixel": float(pixel.detach()), "dice": float(dice.detach()), "seen": float(seen.detach())}


def symmetry(array: np.ndarray, turns: int, mirror: bool) -> np.ndarray:
    """``array`` (H x W or H x W x C) turned by ``turns`` quarter turns, then mirrored left-right."""
    out = np.rot90(array, turns, axes=(0, 1))
    return np.ascontiguousarray(out[:, ::-1] if mirror else out)


def batch_tensors(
    data: Mapping[str, np.ndarray], indices: np.ndarray, rng: np.random.Generator | None = None
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(scene, query, descriptor, labels)`` tensors of the samples ``indices``; with ``rng``
    each sample's scene (with its label) and exemplar get their own random symmetry."""
    scenes, queries, descriptors, labels = [], [], [], []
    for i in indices:
        obs = sample_observation({key: array[i] for key, array in data.items()})
        label = np.asarray(data["label"][i])
        if rng is not None:
            turns, mirror = int(rng.integers(4)), bool(rng.integers(2))
            obs["color"], obs["depth"] = symmetry(obs["color"], turns, mirror), symmetry(obs["depth"], turns, mirror)
            label = symmetry(label, turns, mirror)
            turns, mirror = int(rng.integers(4)), bool(rng.integers(2))
            obs["query_color"] = symmetry(obs["query_color"], turns, mirror)
            obs["query_depth"] = symmetry(obs["query_depth"], turns, mirror)
        scene, query, descriptor = net_inputs(obs)
        scenes.append(scene)
        queries.append(query)
        descriptors.append(descriptor)
        labels.append(label)
    return (
        torch.from_numpy(np.stack(scenes)),
        torch.from_numpy(np.stack(queries)),
        torch.from_numpy(np.stack(descriptors)),
        torch.from_numpy(np.stack(labels).astype(np.uint8)),
    )


def train_locator(
    net: LocatorNet,
    data: Mapping[str, np.ndarray],
    settings: TrainSettings,
    folder: Path,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Train ``net`` on ``data`` (arrays of :data:`~mpg_agents.locator.samples.ARRAYS`) for
    ``settings.steps`` steps, resuming from ``folder/train_state.pt`` when it is there (written
    whole every ``checkpoint_every`` steps and at the end); a CSV of the losses goes to
    ``folder/train_log.csv``. Returns ``{"steps", "seconds"}`` (wall seconds of all sittings)."""
    folder.mkdir(parents=True, exist_ok=True)
    state_path, log_path = folder / "train_state.pt", folder / "train_log.csv"
    optimizer = torch.optim.AdamW(net.parameters(), lr=settings.learning_rate, weight_decay=settings.weight_decay)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda step: learning_rate_factor(step, settings.steps))
    step, seconds = 0, 0.0
    if state_path.is_file():
        state = torch.load(state_path, weights_only=True)
        if state["settings"] != asdict(settings):
            raise ValueError(f"{state_path} was trained with {state['settings']}, not {asdict(settings)}: use a new folder")
        net.load_state_dict(state["net"])
        optimizer.load_state_dict(state["optimizer"])
        schedule.load_state_dict(state["schedule"])
        step, seconds = int(state["step"]), float(state["seconds"])
        log(f"resumed at step {step}")
    count = len(data["label"])
    net.train()
    started = time.perf_counter()
    with log_path.open("a", newline="") as handle:
        writer = csv.writer(handle)
        if step == 0:
            writer.writerow(["step", "loss", "pixel", "dice", "seen", "seconds"])
        while step < settings.steps:
            rng = np.random.default_rng([settings.seed, step])  # the batch depends on the step alone: resumes repeat it
            indices = rng.choice(count, size=settings.batch_size, replace=count < settings.batch_size)
            scene, query, descriptor, labels = batch_tensors(data, indices, rng)
            pixels, seen = net(scene, query, descriptor)
            loss, parts = locator_loss(pixels, seen, labels)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            schedule.step()
            step += 1
            elapsed = seconds + time.perf_counter() - started
            value = float(loss.detach())
            writer.writerow([step, f"{value:.5f}", *(f"{parts[k]:.5f}" for k in ("pixel", "dice", "seen")), f"{elapsed:.1f}"])
            if step % 50 == 0:
                handle.flush()
                log(f"step {step}/{settings.steps}: loss {value:.4f} ({json.dumps(parts)}), {elapsed:.0f} s")
            if step % settings.checkpoint_every == 0 or step == settings.steps:
                state = {
                    "net": net.state_dict(),
                    "optimizer": optimizer.state_dict(),
                    "schedule": schedule.state_dict(),
                    "step": step,
                    "seconds": elapsed,
                    "settings": asdict(settings),
                }
                tmp = state_path.with_name(state_path.name + ".tmp")
                torch.save(state, tmp)
                os.replace(tmp, state_path)
    net.eval()
    return {"steps": step, "seconds": seconds + time.perf_counter() - started}
