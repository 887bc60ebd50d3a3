"""Behaviour cloning: MPGNet's fully convolutional nets trained to copy recorded actions.

One gradient step, as a CleanRL script would write it::

    indices = rng.choice(len(samples), batch_size)            # seeded, without replacement
    obs, actions = samples.batch(indices)
    obs, actions = turn_planes(obs, t), turn_action(actions, t, ...)  # with quarter_turns: t drawn in 0..3
    logits = flat_q(net(obs), primitives)                      # (B, P * 16 * 224 * 224): every rotation of every branch
    # (with rotations_per_sample K < 16: the recorded rotation and K - 1 drawn ones, (B, P * K * 224 * 224))
    loss = imitation_loss(logits, actions)                     # one softmax, cross-entropy of the recorded action
    optimizer.zero_grad(); loss.backward(); optimizer.step()   # Adam

The run folder (:func:`~mpg_agents.learning.run_folder.prepare_run_folder`, locked by
:class:`~mpg_agents.learning.run_folder.RunLock`) holds ``weights.safetensors`` (the net, loadable
by ``mpg-eval --policy`` and ``make_policy``; its header names the dataset, its digest, the
number of demonstrations, the steps and the wall time), ``bc_progress.csv`` (one row per step:
loss, top-1 accuracy, seconds) and ``state/`` (the net, Adam's state, the sample generator and
the counters, swapped in whole: :func:`~mpg_agents.learning.run_state.write_state`). A run
killed at any moment resumes from its last saved state with the same command, and continues
as if it had not stopped (same draws, same weights).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

import mpg_envs  # noqa: F401  (registers the env ids a dataset names)
from mpg_agents.acting.device import resolve_device
from mpg_agents.acting.weights import load_mpgnet_weights, save_mpgnet
from mpg_agents.imitation.augment import turn_action, turn_planes
from mpg_agents.imitation.bc_config import BCConfig, bc_acting_config, bc_net_config
from mpg_agents.imitation.bc_loss import imitation_loss, sampled_rotations, top1_accuracy
from mpg_agents.imitation.demo_samples import DemoSamples, DemoSource
from mpg_agents.learning.run_folder import RunLock, prepare_run_folder, resume_differences
from mpg_agents.learning.run_state import load_optimizer, save_optimizer, state_folder, write_state
from mpg_agents.learning.stop_signal import StopFlag, StopRequested
from mpg_agents.network.mpgnet import MPGNet, flat_q
from mpg_envs.files import write_text_whole
from mpg_envs.grid.workspace import NUM_ROTATIONS
from mpg_envs.simulation.objects import check_not_held_out

WEIGHTS = "weights.safetensors"
PROGRESS = "bc_progress.csv"
PROGRESS_COLUMNS = ("step", "loss", "accuracy", "step_s", "wall_s")
BASELINE = "bc"
LOSS_NAME = "cross-entropy of the recorded flat action under one softmax over every primitive, rotation and pixel"
SAMPLED_LOSS_NAME = (
    "cross-entropy of the recorded flat action under one softmax over every primitive and pixel of the recorded "
    "rotation and {others} others drawn each step (a sampled softmax)"
)


def loss_name(config: BCConfig, num_rotations: int) -> str:
    """What the loss of ``config``'s steps is, in words (the model card's)."""
    if config.rotations_per_sample >= num_rotations:
        return LOSS_NAME
    return SAMPLED_LOSS_NAME.format(others=config.rotations_per_sample - 1)


@dataclass(frozen=True)
class StepRecord:
    """One gradient step: its number (from 1), the batch's loss and top-1 accuracy, its seconds and
    the run's training seconds so far."""

    step: int
    loss: float
    accuracy: float
    step_s: float
    wall_s: float


class ProgressLog:
    """``bc_progress.csv``: a header, then one row per step, appended; rewound to a saved state's
    step when a run resumes, so each step is in it once."""

    def __init__(self, path: Path, resume_at: int) -> None:
        self.path = path
        rows = self._rows_up_to(resume_at) if resume_at and path.is_file() else []
        text = io.StringIO()
        writer = csv.writer(text)
        writer.writerow(PROGRESS_COLUMNS)
        writer.writerows(rows)
        write_text_whole(path, text.getvalue())
        self.file = open(path, "a", newline="")
        self.writer = csv.writer(self.file)

    def _rows_up_to(self, step: int) -> list[list[str]]:
        with open(self.path, newline="") as f:
            rows = list(csv.reader(f))[1:]
        return [r for r in rows if len(r) == len(PROGRESS_COLUMNS) and r[0].isdigit() and int(r[0]) <= step]

    def write(self, record: StepRecord) -> None:
        """Append ``record``'s row."""
        self.writer.writerow(
            [record.step, f"{record.loss:.6f}", f"{record.accuracy:.4f}", f"{record.step_s:.3f}", f"{record.wall_s:.1f}"]
        )

    def sync(self) -> None:
        """Make the rows so far durable (before a state that counts them is saved)."""
        self.file.flush()
        os.fsync(self.file.fileno())

    def close(self) -> None:
        """Close the file."""
        self.file.close()

    def __enter__(self) -> ProgressLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def model_card(source: DemoSource, config: BCConfig, step: int, wall_s: float, loss: float) -> dict[str, Any]:
    """The checkpoint header's ``extra``: how the policy acts (the argmax of its maps: ``max_q``
    over unmasked maps, no loop breaker), the env and what it imitated (the dataset, its digest,
    the number of demonstrations), the steps, the wall time and the last loss."""
    return {
        "coordination": "max_q",
        "grasp_retries": 0,
        "env_id": source.env_id,
        "trained_by": "behaviour cloning (mpg-train --baseline bc)",
        "imitation": {
            "dataset": source.to_dict(),
            "demo_episodes": source.episodes,
            "steps": step,
            "steps_asked": config.steps,
            "batch_size": config.batch_size,
            "learning_rate": config.learning_rate,
            "rotations_per_sample": config.rotations_per_sample,
            "quarter_turns": config.quarter_turns,
            "grasp_fingers": config.grasp_fingers,
            "seed": config.seed,
            "wall_time_s": round(wall_s, 1),
            "last_loss": None if math.isnan(loss) else round(loss, 6),
            "loss": loss_name(config, NUM_ROTATIONS),
        },
    }


def run_record(config: BCConfig, source: DemoSource) -> dict[str, Any]:
    """What a run saves of its settings and data, and a resume must match."""
    return {
        "baseline": BASELINE,
        "settings": config.run_record(),
        "dataset_digest": source.digest,
        "demo_episodes": source.episodes,
        "action_primitives": list(source.action_primitives),
    }


def check_bc_resume(out: Path, saved: Mapping[str, Any], asked: Mapping[str, Any], resume_anyway: bool) -> list[str]:
    """The differences between a saved behaviour-cloning run and the one asked for.

    Raises:
        ValueError: the folder holds another kind of run, or a different one without ``resume_anyway``.
    """
    if saved.get("baseline") != BASELINE:
        raise ValueError(f"{out} holds an MPGNet training run, not behaviour cloning: give another --out")
    changed = resume_differences(saved, asked)
    if changed and not resume_anyway:
        raise ValueError(
            f"{out} holds a behaviour-cloning run with other settings or data ({'; '.join(changed)}): give the run's own, "
            "another --out, or --resume-anyway to continue it with the new ones"
        )
    return changed


def save_bc_state(
    out: Path,
    net: MPGNet,
    optimizer: torch.optim.Optimizer,
    rng: np.random.Generator,
    counters: dict[str, Any],
    record: dict[str, Any],
) -> None:
    """The run's state, swapped in whole."""

    def writer(tmp: Path) -> None:
        save_mpgnet(net, tmp / "online.safetensors")
        save_optimizer(optimizer, tmp)
        write_text_whole(tmp / "rng.json", json.dumps({"numpy": rng.bit_generator.state}))
        write_text_whole(tmp / "counters.json", json.dumps(counters))
        write_text_whole(tmp / "config.json", json.dumps(record))

    write_state(out, writer)


def draw_batch(rng: np.random.Generator, samples: int, batch_size: int) -> np.ndarray:
    """``batch_size`` sample indices: without replacement, or with it when there are fewer samples."""
    return rng.choice(samples, size=batch_size, replace=samples < batch_size)


def refuse_held_out(source: DemoSource) -> None:
    """Refuse demonstrations recorded on objects held out for testing (the unseen-object track), as
    ``mpg-train`` refuses to train on them: the dataset's env is built from its id and keywords and
    its object set checked (:func:`~mpg_envs.simulation.objects.check_not_held_out`).

    Raises:
        mpg_envs.simulation.objects.HeldOutObjectsError: the dataset's objects are held out.
    """
    what = f"behaviour cloning on demonstrations recorded on {source.env_id}"
    kwargs = dict(source.env_kwargs)
    check_not_held_out(kwargs.get("object_set", gym.spec(source.env_id).kwargs.get("object_set", "blocks")), what=what)
    env = gym.make(source.env_id, **kwargs)
    try:
        check_not_held_out("custom", env.unwrapped.object_set, what)  # type: ignore[attr-defined]  # an MPG env
    finally:
        env.close()


def step_logits(
    net: MPGNet,
    batch: Mapping[str, torch.Tensor],
    actions: np.ndarray,
    primitives: tuple[str, ...],
    config: BCConfig,
    rng: np.random.Generator,
) -> tuple[torch.Tensor, torch.Tensor]:
    """One step's flat logits and classes: over every rotation (the exact loss), or over the
    recorded rotation and ``rotations_per_sample - 1`` drawn others (a sampled softmax)."""
    device = next(net.parameters()).device
    r = net.config.num_rotations
    if config.rotations_per_sample >= r:
        return flat_q(net(batch, primitives), primitives), torch.from_numpy(actions).to(device)
    size = net.config.heightmap_size
    rotations, classes = sampled_rotations(rng, actions, config.rotations_per_sample, r, size * size)
    maps = net.maps_from(net.encode(batch, rotations=torch.from_numpy(rotations).to(device)), primitives)
    return flat_q(maps, primitives), torch.from_numpy(classes).to(device)


def train_bc(
    config: BCConfig,
    demos: str | Path,
    out: str | Path,
    resume_anyway: bool = False,
    on_step: Callable[[StepRecord], None] | None = None,
) -> dict[str, Any]:
    """Train (or resume) a behaviour-cloning run of ``config`` on the dataset ``demos`` in ``out``.

    Returns:
        A summary: the checkpoint, the steps done, the last loss, the wall time and the dataset record.

    Raises:
        ValueError: a bad dataset or number of demonstrations (:class:`DemoSamples`), a run folder
            that holds something else or another run (:func:`check_bc_resume`).
        mpg_envs.simulation.objects.HeldOutObjectsError: demonstrations of objects held out for
            testing (:func:`refuse_held_out`).
        mpg_agents.learning.run_folder.RunFolderBusy: another process trains in ``out``.
    """
    samples = DemoSamples(demos, config.demo_episodes, color=config.color_input)
    source = samples.source
    refuse_held_out(source)  # before the run folder exists: nothing is written
    device = resolve_device(config.device)
    folder = prepare_run_folder(out)
    lock = RunLock(folder)
    try:
        torch.manual_seed(config.seed)
        torch.set_flush_denormal(True)
        net = MPGNet(bc_net_config(config, source.action_primitives)).to(device)
        acting = bc_acting_config(config, net.config)  # what the saved policy acts with
        optimizer = torch.optim.Adam(net.parameters(), lr=config.learning_rate)
        rng = np.random.default_rng(config.seed)
        record = run_record(config, source)
        step, wall_s, loss = 0, 0.0, float("nan")
        saved = state_folder(folder)
        if saved is not None:
            check_bc_resume(folder, json.loads((saved / "config.json").read_text()), record, resume_anyway)
            load_mpgnet_weights(net, saved / "online.safetensors")
            load_optimizer(optimizer, saved)
            rng.bit_generator.state = json.loads((saved / "rng.json").read_text())["numpy"]
            counters = json.loads((saved / "counters.json").read_text())
            step, wall_s, loss = int(counters["step"]), float(counters["wall_s"]), float(counters["loss"])
        # SIGINT/SIGTERM while it runs: the step just taken is saved, then the run stops.
        with ProgressLog(folder / PROGRESS, resume_at=step) as log, StopFlag() as stop:
            net.train()
            while step < config.steps:
                start = time.perf_counter()
                obs, actions = samples.batch(draw_batch(rng, len(samples), config.batch_size))
                if config.quarter_turns:
                    turns = rng.integers(4, size=actions.size)
                    obs = turn_planes(obs, turns)
                    actions = turn_action(actions, turns, net.config.num_rotations, net.config.heightmap_size)
                batch = {k: torch.from_numpy(v).to(device) for k, v in obs.items()}
                logits, target = step_logits(net, batch, actions, source.action_primitives, config, rng)
                loss_t = imitation_loss(logits, target)
                optimizer.zero_grad()
                loss_t.backward()
                optimizer.step()
                step += 1
                loss = float(loss_t.detach())
                seconds = time.perf_counter() - start
                wall_s += seconds
                done = StepRecord(step, loss, top1_accuracy(logits.detach(), target), seconds, wall_s)
                log.write(done)
                if on_step is not None:
                    on_step(done)
                if step % config.save_every == 0 or step == config.steps or stop.asked:
                    log.sync()
                    save_mpgnet(net, folder / WEIGHTS, extra=model_card(source, config, step, wall_s, loss), config=acting)
                    save_bc_state(folder, net, optimizer, rng, {"step": step, "wall_s": wall_s, "loss": loss}, record)
                if stop.asked and step < config.steps:
                    raise StopRequested()
            if not (folder / WEIGHTS).is_file():  # a finished run resumed with its own steps
                save_mpgnet(net, folder / WEIGHTS, extra=model_card(source, config, step, wall_s, loss), config=acting)
    finally:
        lock.release()
    return {
        "weights": str(folder / WEIGHTS),
        "steps": step,
        "last_loss": loss,
        "wall_time_s": round(wall_s, 1),
        "dataset": source.to_dict(),
    }
