"""A training run's resumable state on disk (not the network's weight format: see
:mod:`mpg_agents.acting.weights`), without pickle.

A run directory holds ``weights.safetensors`` (the online MPGNet, usable on its own) and a
``state/`` folder: the target network (safetensors), the optimiser (tensors in safetensors,
its scalar settings in JSON), the replay buffer (``replay.npz``: each distinct compressed
observation once, transitions as indices into them), the random generators and the
counters (:class:`Counters`, JSON). Everything is written to a temporary folder first and
swapped in whole, so a run killed while saving still has its previous state; a save the disk
refuses removes the temporary folder and raises :class:`~mpg_envs.files.WriteFailed` naming the
file, the previous state kept.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors.torch import load_file, save

from mpg_agents.acting.grasp_threshold import from_header
from mpg_agents.acting.weights import load_mpgnet_weights, save_mpgnet
from mpg_agents.learning.replay import PrioritizedHeightmapReplayBuffer
from mpg_agents.learning.replay_codec import Frame
from mpg_agents.network.mpgnet import MPGNet
from mpg_envs.files import WriteFailed, write_bytes_whole, write_text_whole, written_whole

STATE_FORMAT = "mpg-train-state-v1"


@dataclass
class Counters:
    """Progress of a run (saved with the state)."""

    iteration: int = 0
    episode: int = 0  # one actor: the running (or next) episode's index; with actors: the episodes handed out
    episode_motions: int = 0
    failed_grasps_in_a_row: int = 0
    pushes_in_episode: int = 0
    gradient_steps: int = 0
    window_grasps: int = 0
    window_target_grasps: int = 0
    # The Q of the last 200 greedy grasps that took the target (a calibrates_q_star stage's estimate).
    successful_grasp_q: list[float] = field(default_factory=list)
    calibrated_at: int = -1  # iteration of the last in-scene Q*_g calibration (-1: none)
    grasp_trials: int = 0  # grasps tried in the simulation and undone (TrainingStage.grasp_trials)
    grasp_trial_targets: int = 0  # of those, the ones that took the target
    move_trials: int = 0  # moves tried in the simulation and undone (TrainingStage.move_trials)
    move_trial_successes: int = 0  # of those, the ones that uncovered the target
    rival_trials: int = 0  # covered-target moves and pushes tried as the other (TrainingStage.rival_trials)
    rival_trial_clears: int = 0  # of those, the ones that uncovered the target
    # Covered-target moves and pushes tried as the best grasp (TrainingStage.covered_grasp_trials).
    covered_grasp_trials: int = 0
    covered_grasp_trial_targets: int = 0  # of those, the ones that took the target
    skipped_scenes: int = 0  # training episodes whose seed gave no valid scene (logged, see seeds.reset_first_valid)
    replay_credit: float = 0.0  # gradient steps earned at TrainConfig.replay_ratio and not yet taken (a fraction)


def save_replay(buffer: PrioritizedHeightmapReplayBuffer, path: Path) -> None:
    """Write the buffer's transitions, priorities and compressed frames to ``path`` (npz)."""
    n = buffer.size()
    frames: dict[int, int] = {}
    blobs: list[Frame] = []

    def index(frame: Frame) -> int:
        if id(frame) not in frames:
            frames[id(frame)] = len(blobs)
            blobs.append(frame)
        return frames[id(frame)]

    obs_idx = np.array([[index(f) for f in row] for row in buffer.obs_frames[:n]], dtype=np.int64).reshape(n, buffer.n_envs)
    next_idx = np.array([[index(f) for f in row] for row in buffer.next_obs_frames[:n]], dtype=np.int64).reshape(
        n, buffer.n_envs
    )
    arrays: dict[str, Any] = {  # np.savez's keywords
        "obs_idx": obs_idx,
        "next_idx": next_idx,
        "actions": buffer.actions[:n],
        "rewards": buffer.rewards[:n],
        "dones": buffer.dones[:n],
        "timeouts": buffer.timeouts[:n],
        "priorities": buffer.priorities[:n],
        "meta": np.array([buffer.pos, int(buffer.full), n], dtype=np.int64),
        "max_priority": np.array(buffer.max_priority),
    }
    keys = sorted(buffer.codecs)
    for k, frame in enumerate(blobs):
        for key in keys:
            kind, blob = frame.planes[key]
            arrays[f"f{k}/{key}/{kind}"] = np.frombuffer(blob, dtype=np.uint8)
    with written_whole(path) as tmp:
        np.savez(tmp, **arrays)


def load_replay(buffer: PrioritizedHeightmapReplayBuffer, path: Path) -> None:
    """Restore a :func:`save_replay` file into an empty buffer of the same spaces."""
    with np.load(path, allow_pickle=False) as data:
        pos, full, n = (int(v) for v in data["meta"])
        planes: dict[int, dict[str, tuple[str, bytes]]] = {}
        for name in data.files:
            if name.startswith("f") and "/" in name:
                k, key, kind = name.split("/")
                planes.setdefault(int(k[1:]), {})[key] = (kind, data[name].tobytes())
        frames = [Frame(planes[k]) for k in range(len(planes))]
        if n > buffer.buffer_size:
            raise ValueError(f"saved replay holds {n} transitions, more than the buffer's capacity {buffer.buffer_size}")
        for i in range(n):
            for e in range(buffer.n_envs):
                buffer.obs_frames[i, e] = frames[int(data["obs_idx"][i, e])]
                buffer.next_obs_frames[i, e] = frames[int(data["next_idx"][i, e])]
        buffer.actions[:n] = data["actions"]
        buffer.rewards[:n] = data["rewards"]
        buffer.dones[:n] = data["dones"]
        buffer.timeouts[:n] = data["timeouts"]
        buffer.priorities[:n] = data["priorities"]
        buffer.max_priority = float(data["max_priority"])
    buffer.pos, buffer.full = pos, bool(full)
    # The next add starts a fresh episode: nothing to share with the last stored frame.
    buffer.forget_last_frames()


def save_optimizer(optimizer: torch.optim.Optimizer, folder: Path) -> None:
    state = optimizer.state_dict()
    tensors = {}
    scalars: dict[str, Any] = {"param_groups": state["param_groups"], "state": {}}
    for pid, pstate in state["state"].items():
        scalars["state"][str(pid)] = {}
        for name, value in pstate.items():
            if isinstance(value, torch.Tensor):
                tensors[f"{pid}/{name}"] = value.detach().cpu().contiguous()
            else:
                scalars["state"][str(pid)][name] = value
    write_bytes_whole(folder / "optimizer.safetensors", save(tensors))
    write_text_whole(folder / "optimizer.json", json.dumps(scalars))


def load_optimizer(optimizer: torch.optim.Optimizer, folder: Path) -> None:
    tensors = load_file(str(folder / "optimizer.safetensors"))
    scalars = json.loads((folder / "optimizer.json").read_text())
    state: dict[int, dict[str, Any]] = {int(pid): dict(values) for pid, values in scalars["state"].items()}
    for name, value in tensors.items():
        pid, key = name.split("/", 1)
        state.setdefault(int(pid), {})[key] = value
    optimizer.load_state_dict({"state": state, "param_groups": scalars["param_groups"]})


def write_state(run_dir: Path, writer) -> None:
    """Call ``writer(tmp_folder)`` and swap the result in as ``run_dir/state`` atomically.

    Raises:
        WriteFailed: the disk refused a file (the temporary folder is removed, the previous
            state kept).
    """
    tmp = run_dir / "state.tmp"
    if tmp.exists():
        shutil.rmtree(tmp)
    try:
        tmp.mkdir(parents=True)
        writer(tmp)
        write_text_whole(tmp / "FORMAT", STATE_FORMAT)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(exc, OSError) and not isinstance(exc, WriteFailed):
            raise WriteFailed(tmp, exc.strerror or str(exc)) from None
        raise
    final = run_dir / "state"
    old = run_dir / "state.old"
    if final.exists():
        final.rename(old)
    tmp.rename(final)
    if old.exists():
        shutil.rmtree(old)


def state_folder(run_dir: Path) -> Path | None:
    """The run's saved state folder, or ``None`` when there is nothing to resume."""
    for name in ("state", "state.old"):  # state.old survives a kill between the two renames
        folder = run_dir / name
        if (folder / "FORMAT").is_file() and (folder / "FORMAT").read_text() == STATE_FORMAT:
            return folder
    return None


COUNTERS_FILE = "counters.json"
"""The saved state's counters (:class:`Counters` as JSON)."""


def save_run_state(
    run_dir: Path,
    *,
    online: MPGNet,
    target: MPGNet,
    q_star: float | None,
    optimizer: torch.optim.Optimizer,
    replay: PrioritizedHeightmapReplayBuffer,
    rng: np.random.Generator,
    counters: dict[str, Any],
    config: dict[str, Any],
) -> None:
    """Write everything a run needs to continue (atomically, see :func:`write_state`); Q*_g
    goes into the online network's weights header."""

    def writer(tmp: Path) -> None:
        save_mpgnet(online, tmp / "online.safetensors", q_star=q_star)
        save_mpgnet(target, tmp / "target.safetensors")
        save_optimizer(optimizer, tmp)
        save_replay(replay, tmp / "replay.npz")
        rngs = {"numpy": rng.bit_generator.state, "replay": replay.rng_state, "torch": torch.get_rng_state().tolist()}
        write_text_whole(tmp / "rng.json", json.dumps(rngs))
        write_text_whole(tmp / COUNTERS_FILE, json.dumps(counters))
        write_text_whole(tmp / "config.json", json.dumps(config))

    write_state(run_dir, writer)


def load_run_state(
    folder: Path,
    *,
    online: MPGNet,
    target: MPGNet,
    optimizer: torch.optim.Optimizer,
    replay: PrioritizedHeightmapReplayBuffer,
    rng: np.random.Generator,
) -> tuple[dict[str, Any], dict[str, Any], float | None]:
    """Restore a :func:`save_run_state` folder into the given objects; returns the saved
    ``(counters, config, Q*_g)`` (Q*_g ``None`` when the run had none)."""
    header = load_mpgnet_weights(online, folder / "online.safetensors")
    load_mpgnet_weights(target, folder / "target.safetensors")
    load_optimizer(optimizer, folder)
    load_replay(replay, folder / "replay.npz")
    rngs = json.loads((folder / "rng.json").read_text())
    rng.bit_generator.state = rngs["numpy"]
    replay.rng_state = rngs["replay"]
    torch.set_rng_state(torch.tensor(rngs["torch"], dtype=torch.uint8))
    counters, config = json.loads((folder / COUNTERS_FILE).read_text()), json.loads((folder / "config.json").read_text())
    return counters, config, from_header(header)
