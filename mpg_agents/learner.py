"""The DQN learner of MPGNet for one training stage (paper Sections III-C and III-D).

One iteration: observe, decide (the paper's coordination, epsilon-greedy exploration inside
the target's rough region, the heuristic grasp after two failed grasps), act, store the
transition, and take one gradient step on a prioritised batch: Huber loss on the chosen
pixel only, double-DQN target ``y = r + gamma * Q_target(s', argmax_a Q(s', a))``, grasp
symmetry (rotation ``r`` also trains ``r + 8``), priorities updated to ``|Q - y|``.

Everything needed to continue is saved every ``checkpoint_every`` iterations and when the
process is asked to stop (SIGINT/SIGTERM): a killed run resumes with the same counters,
replay, weights, optimiser and random generators. An episode interrupted by the kill is
started afresh (its scene comes from the episode counter, so it is the same scene).
"""

from __future__ import annotations

import csv
import json
import math
import signal
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Callable

import gymnasium as gym
import numpy as np
import torch
from torch.nn import functional as F

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_agents.dqn import td_targets
from mpg_agents.checkpoint import (
    load_optimizer,
    load_replay,
    save_optimizer,
    save_replay,
    state_folder,
    write_state,
)
from mpg_agents.heuristics import heuristic_grasp
from mpg_agents.mpgnet import load_mpgnet_weights, save_mpgnet
from mpg_agents.policy import GraspScorer, MPGNetPolicy
from mpg_agents.replay import PrioritizedHeightmapReplayBuffer
from mpg_envs.actions import PRIMITIVES, encode_action
from mpg_envs.workspace import NUM_ROTATIONS


@dataclass
class TrainConfig:
    """One stage's training settings; defaults are the paper's where it gives them."""

    env_id: str = "MPG-Stage2-v0"
    steps: int = 1000  # training iterations (one env step + one gradient step each)
    seed: int = 0
    variant: str = "small"
    num_objects: int | None = None  # None: the stage's own count
    # Paper, Training Details.
    gamma: float = 0.5
    learning_rate: float = 1e-4
    weight_decay: float = 2**-5
    betas: tuple[float, float] = (0.9, 0.99)
    epsilon_start: float = 0.5
    epsilon_end: float = 0.1
    epsilon_decay_steps: int = 1000
    # Replay and updates.
    batch_size: int = 2
    replay_capacity: int = 5000
    priority_alpha: float = 1.0
    target_update_every: int = 100
    grasp_symmetry: bool = True
    # Training aids (paper, Simulation Experiments).
    heuristic_after_failed_grasps: int = 2
    # Which branches learn (None: the env's primitives); the rest stay frozen.
    trainable: tuple[str, ...] | None = None
    # Stage V: train the nets in turn, switching every this many iterations (0: no alternation).
    alternate_every: int = 0
    coordination: str = "workflow"  # or "max_q" (the paper's "w/o alternating training" ablation)
    q_star: float = float("nan")
    # Stage III curriculum: objects grow from ``num_objects_start`` to ``num_objects`` over the stage.
    num_objects_start: int | None = None
    # The fixed Stage II grasp net that scores states for the move/push rewards.
    discriminator: str | None = None
    # Bookkeeping.
    checkpoint_every: int = 100
    window: int = 200  # grasp success rate per this many iterations (paper)
    torch_threads: int = 2
    net_config: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["betas"] = list(self.betas)
        data["trainable"] = list(self.trainable) if self.trainable is not None else None
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "TrainConfig":
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown training settings {unknown}; valid: {sorted(known)}")
        data = dict(data)
        if "betas" in data:
            data["betas"] = tuple(data["betas"])
        if data.get("trainable") is not None:
            data["trainable"] = tuple(data["trainable"])
        return cls(**data)


@dataclass
class Counters:
    """Progress of a run (saved with the state)."""

    iteration: int = 0
    episode: int = 0
    episode_motions: int = 0
    failed_grasps_in_a_row: int = 0
    pushes_in_episode: int = 0
    gradient_steps: int = 0
    window_grasps: int = 0
    window_target_grasps: int = 0
    successful_grasp_q: list[float] = field(default_factory=list)  # for Q*_g calibration


class StopRequested(Exception):
    """Raised inside the loop when SIGINT/SIGTERM arrived; the state is saved first."""


class Learner:
    """Trains an MPGNet on one env; ``run()`` does ``config.steps`` iterations (resumable)."""

    def __init__(self, config: TrainConfig, out: str | Path, init: str | Path | None = None, log: Callable[[str], None] = print):
        self.config = config
        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.log = log
        torch.set_num_threads(config.torch_threads)
        # A young network's eval-mode activations go denormal and slow the CPU down 10x.
        torch.set_flush_denormal(True)
        self.env = self._make_env(config.num_objects_start or config.num_objects)
        env = self.env.unwrapped
        self.primitives: tuple[str, ...] = env.primitives
        self.trainable = tuple(config.trainable) if config.trainable is not None else self.primitives
        bad = [p for p in self.trainable if p not in PRIMITIVES]
        if bad:
            raise ValueError(f"trainable branches must be among {PRIMITIVES}, got {bad}")
        self.policy = MPGNetPolicy(
            env.observation_space,
            env.action_space,
            lambda _: config.learning_rate,
            variant=config.variant,
            branches=PRIMITIVES,
            coordination=config.coordination,
            q_star=config.q_star,
            net_config=config.net_config,
            optimizer_kwargs={"weight_decay": config.weight_decay, "betas": tuple(config.betas)},
        )
        self.net = self.policy.q_net.mpgnet
        self.target = self.policy.q_net_target.mpgnet
        self.optimizer = self.policy.optimizer
        if init is not None:
            header = load_mpgnet_weights(self.net, init, strict_branches=False)
            self.target.load_state_dict(self.net.state_dict())
            if math.isnan(config.q_star) and header.get("q_star") is not None:
                self.policy.set_q_star(float(header["q_star"]))
        if not math.isnan(config.q_star):
            self.policy.set_q_star(config.q_star)
        self.replay = PrioritizedHeightmapReplayBuffer(
            config.replay_capacity, env.observation_space, env.action_space, device="cpu", alpha=config.priority_alpha, seed=config.seed
        )
        self.rng = np.random.default_rng(config.seed)
        torch.manual_seed(config.seed)
        self.counters = Counters()
        self._stop = False
        self._writer = None
        self._csv = None
        self._resume()

    # ----------------------------------------------------------------- setup
    def _make_env(self, num_objects: int | None) -> gym.Env:
        kwargs: dict[str, Any] = {}
        if num_objects is not None:
            kwargs["num_objects"] = num_objects
        if self.config.discriminator is not None:
            kwargs["grasp_scorer"] = GraspScorer.from_weights(self.config.discriminator)
        return gym.make(self.config.env_id, **kwargs)

    def _resume(self) -> None:
        folder = state_folder(self.out)
        if folder is None:
            return
        saved = json.loads((folder / "config.json").read_text())
        if saved["env_id"] != self.config.env_id or saved["variant"] != self.config.variant:
            raise ValueError(
                f"{self.out} holds a run of {saved['env_id']} ({saved['variant']}); "
                f"asked for {self.config.env_id} ({self.config.variant}): use another --out"
            )
        load_mpgnet_weights(self.net, folder / "online.safetensors")
        load_mpgnet_weights(self.target, folder / "target.safetensors")
        load_optimizer(self.optimizer, folder)
        load_replay(self.replay, folder / "replay.npz")
        rng = json.loads((folder / "rng.json").read_text())
        self.rng.bit_generator.state = rng["numpy"]
        if self.replay._rng is not None:
            self.replay._rng.bit_generator.state = rng["replay"]
        torch.set_rng_state(torch.tensor(rng["torch"], dtype=torch.uint8))
        self.counters = Counters(**json.loads((folder / "counters.json").read_text()))
        q_star = saved.get("q_star_now")
        if q_star is not None:
            self.policy.set_q_star(q_star)
        self.log(f"resuming {self.out} at iteration {self.counters.iteration} (replay {self.replay.size()})")

    def save_state(self) -> None:
        """Write weights and the full resumable state (atomically)."""

        def writer(tmp: Path) -> None:
            save_mpgnet(self.net, tmp / "online.safetensors", q_star=self.policy.q_star)
            save_mpgnet(self.target, tmp / "target.safetensors", q_star=self.policy.q_star)
            save_optimizer(self.optimizer, tmp)
            save_replay(self.replay, tmp / "replay.npz")
            rng = {
                "numpy": self.rng.bit_generator.state,
                "replay": self.replay._rng.bit_generator.state if self.replay._rng is not None else None,
                "torch": torch.get_rng_state().tolist(),
            }
            (tmp / "rng.json").write_text(json.dumps(rng))
            (tmp / "counters.json").write_text(json.dumps(asdict(self.counters)))
            (tmp / "config.json").write_text(json.dumps(json_safe({**self.config.to_dict(), "q_star_now": self.policy.q_star})))

        write_state(self.out, writer)
        save_mpgnet(self.net, self.out / "weights.safetensors", q_star=self.policy.q_star, extra={"env_id": self.config.env_id})

    # ------------------------------------------------------------------ loop
    def run(self) -> dict[str, Any]:
        """Train until ``config.steps`` iterations are done; returns the final summary."""
        cfg = self.config
        from torch.utils.tensorboard import SummaryWriter
        from tqdm import tqdm

        self._writer = SummaryWriter(str(self.out / "tb"))
        new_csv = not (self.out / "progress.csv").exists()
        csv_file = open(self.out / "progress.csv", "a", newline="")
        self._csv = csv.writer(csv_file)
        if new_csv:
            self._csv.writerow(CSV_COLUMNS)
        handlers = {s: signal.signal(s, self._request_stop) for s in (signal.SIGINT, signal.SIGTERM)}
        bar = tqdm(total=cfg.steps, initial=self.counters.iteration, desc=cfg.env_id, unit="it", dynamic_ncols=True)
        obs = self._reset_episode()
        try:
            while self.counters.iteration < cfg.steps:
                obs = self.iteration(obs)
                bar.update(1)
                if self.counters.iteration % cfg.checkpoint_every == 0 or self.counters.iteration == cfg.steps:
                    self.save_state()
                if self._stop:
                    self.save_state()
                    raise StopRequested()
        finally:
            bar.close()
            for s, h in handlers.items():
                signal.signal(s, h)
            csv_file.close()
            self._writer.close()
        return {"iteration": self.counters.iteration, "episodes": self.counters.episode, "q_star": self.calibrated_q_star()}

    def _request_stop(self, signum, frame) -> None:
        self._stop = True

    def _reset_episode(self) -> dict[str, np.ndarray]:
        c = self.counters
        self._maybe_grow_scene()
        obs, _ = self.env.reset(seed=self.config.seed * 1_000_003 + c.episode)
        c.episode_motions = c.failed_grasps_in_a_row = c.pushes_in_episode = 0
        return obs

    def _maybe_grow_scene(self) -> None:
        """Stage III curriculum: more objects as the stage goes on."""
        cfg = self.config
        if cfg.num_objects_start is None or cfg.num_objects is None:
            return
        frac = min(1.0, self.counters.iteration / max(1, cfg.steps))
        n = int(round(cfg.num_objects_start + frac * (cfg.num_objects - cfg.num_objects_start)))
        if n != self.env.unwrapped.num_objects:
            self.env.close()
            self.env = self._make_env(n)

    def epsilon(self) -> float:
        cfg = self.config
        frac = min(1.0, self.counters.iteration / max(1, cfg.epsilon_decay_steps))
        return cfg.epsilon_start + frac * (cfg.epsilon_end - cfg.epsilon_start)

    def active_branches(self) -> tuple[str, ...]:
        """The branches learning this iteration (Stage V trains them in turn)."""
        if self.config.alternate_every <= 0:
            return self.trainable
        turn = (self.counters.iteration // self.config.alternate_every) % len(self.trainable)
        return (self.trainable[turn],)

    def iteration(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        c = self.counters
        start = time.perf_counter()
        action, primitive, how, q_value = self.act(obs)
        t_decide = time.perf_counter() - start
        next_obs, reward, terminated, truncated, info = self.env.step(action)
        t_act = time.perf_counter() - start - t_decide
        self.replay.add(
            {k: v[None] for k, v in obs.items()},
            {k: v[None] for k, v in next_obs.items()},
            np.array([[action]]),
            np.array([reward], dtype=np.float32),
            np.array([terminated], dtype=np.float32),
            [{}],
        )
        loss = self.learn()
        c.iteration += 1
        c.episode_motions += 1
        if primitive == "grasp":
            c.window_grasps += 1
            c.window_target_grasps += int(info["target_grasped"])
            c.failed_grasps_in_a_row = 0 if info["grasp_success"] else c.failed_grasps_in_a_row + 1
            if info["target_grasped"] and how == "greedy" and math.isfinite(q_value):
                c.successful_grasp_q = (c.successful_grasp_q + [q_value])[-200:]
        if primitive == "push":
            c.pushes_in_episode += 1
        t_total = time.perf_counter() - start
        self._record(primitive, how, reward, loss, info, t_decide, t_act, t_total)
        if terminated or truncated:
            self._episode_end(info)
            c.episode += 1
            return self._reset_episode()
        return next_obs

    # ------------------------------------------------------------ deciding
    def act(self, obs: dict[str, np.ndarray]) -> tuple[int, str, str, float]:
        """``(action, primitive, how, q)``: how is "greedy", "explore" or "heuristic"."""
        c = self.counters
        env = self.env.unwrapped
        # Stage IV: five pushes, then the grasp.
        forced = "grasp" if env.spec_stage.end_after_grasp and c.pushes_in_episode >= 5 and "grasp" in self.primitives else None
        decision = self.policy.decide(obs, forced)
        primitive = decision.primitive
        if primitive == "grasp" and self.config.heuristic_after_failed_grasps and c.failed_grasps_in_a_row >= self.config.heuristic_after_failed_grasps and obs["mask"].any():
            rot, row, col = heuristic_grasp(obs)
            return encode_action(self.primitives, "grasp", rot, row, col), "grasp", "heuristic", float("nan")
        if self.rng.random() < self.epsilon():
            if self.config.coordination == "max_q":
                primitive = self.primitives[int(self.rng.integers(len(self.primitives)))]
            rot, row, col = self._explore_pixel(obs, primitive)
            return encode_action(self.primitives, primitive, rot, row, col), primitive, "explore", float("nan")
        action = encode_action(self.primitives, primitive, decision.rotation, decision.row, decision.col)
        return action, primitive, "greedy", float(decision.q_value)

    def _explore_pixel(self, obs: dict[str, np.ndarray], primitive: str) -> tuple[int, int, int]:
        """A random rotation and a random pixel where the primitive can matter.

        Move and grasp: inside the target's bounding rectangle (the rough mask). Push: within
        5 cm of it. An empty mask falls back to any occupied pixel, then to any pixel.
        """
        mask = obs["mask"] > 0
        size = mask.shape[0]
        if mask.any():
            rows, cols = np.nonzero(mask)
            pad = 25 if primitive == "push" else 0
            r0, r1 = max(rows.min() - pad, 0), min(rows.max() + pad, size - 1)
            c0, c1 = max(cols.min() - pad, 0), min(cols.max() + pad, size - 1)
            row, col = int(self.rng.integers(r0, r1 + 1)), int(self.rng.integers(c0, c1 + 1))
        else:
            occupied = np.argwhere(obs["depth"] > 0.005)
            if len(occupied):
                row, col = (int(v) for v in occupied[self.rng.integers(len(occupied))])
            else:
                row, col = (int(v) for v in self.rng.integers(size, size=2))
        return int(self.rng.integers(NUM_ROTATIONS)), row, col

    # ------------------------------------------------------------ learning
    def learn(self) -> float:
        """One gradient step on a prioritised batch; returns the loss (NaN when nothing learnt)."""
        cfg = self.config
        if self.replay.size() == 0:
            return float("nan")
        q_net = self.policy.q_net
        batch = self.replay.sample(min(cfg.batch_size, self.replay.size()))
        actions = batch.actions.reshape(-1).long()
        targets = td_targets(q_net, self.policy.q_net_target, batch.next_observations, batch.rewards, batch.dones, cfg.gamma)
        prim, rot, _, _ = q_net.split_actions(actions)
        active = set(self.active_branches())
        sel = torch.tensor([i for i, p in enumerate(prim.tolist()) if self.primitives[p] in active], dtype=torch.long)
        if sel.numel() == 0:
            return float("nan")  # every sampled transition belongs to a frozen branch
        obs = {k: v[sel] for k, v in batch.observations.items()}
        acts, ys = actions[sel], targets[sel]
        if cfg.grasp_symmetry and "grasp" in self.primitives:
            # A parallel-jaw grasp at rotation r is the grasp at r + 8: train both.
            sym = torch.nonzero(prim[sel] == self.primitives.index("grasp")).flatten()
            if sym.numel():
                size = self.net.config.heightmap_size
                turned = acts[sym] + (torch.where(rot[sel][sym] < NUM_ROTATIONS // 2, 1, -1) * (NUM_ROTATIONS // 2) * size * size)
                obs = {k: torch.cat([v, v[sym]]) for k, v in obs.items()}
                acts, ys = torch.cat([acts, turned]), torch.cat([ys, ys[sym]])
        q_net.set_training_mode(True)
        q = q_net.q_values_at(obs, acts)
        loss = F.smooth_l1_loss(q, ys)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        self.counters.gradient_steps += 1
        surprise = np.zeros(len(actions))
        surprise[sel.numpy()] = (q[: len(sel)] - ys[: len(sel)]).abs().detach().reshape(-1).numpy()
        self.replay.update_priorities(batch.indices, surprise)
        if self.counters.gradient_steps % cfg.target_update_every == 0:
            self.target.load_state_dict(self.net.state_dict())
        return float(loss.detach())

    # ------------------------------------------------------------ logging
    def _record(self, primitive, how, reward, loss, info, t_decide, t_act, t_total) -> None:
        c, cfg = self.counters, self.config
        it = c.iteration
        w = self._writer
        w.add_scalar("train/loss", loss, it)
        w.add_scalar("train/epsilon", self.epsilon(), it)
        w.add_scalar("train/reward", reward, it)
        w.add_scalar("time/iteration_s", t_total, it)
        rate = ""
        if it % cfg.window == 0 and c.window_grasps:
            rate = c.window_target_grasps / c.window_grasps
            w.add_scalar("train/grasp_success_rate", rate, it)
            c.window_grasps = c.window_target_grasps = 0
        self._csv.writerow(
            [it, c.episode, primitive, how, f"{reward:.3f}", f"{loss:.5f}", f"{self.epsilon():.4f}", int(info["grasp_success"]),
             int(info["target_grasped"]), int(info["is_success"]), info["num_motions"], rate if rate == "" else f"{rate:.4f}",
             f"{t_decide:.3f}", f"{t_act:.3f}", f"{t_total:.3f}"]
        )

    def _episode_end(self, info: dict[str, Any]) -> None:
        self._writer.add_scalar("train/motions_per_episode", info["num_motions"], self.counters.iteration)
        self._writer.add_scalar("train/task_success", float(info["is_success"]), self.counters.iteration)

    def calibrated_q_star(self) -> float:
        """Q*_g: the median Q of the recent successful greedy target grasps (NaN if none)."""
        values = self.counters.successful_grasp_q
        return float(np.median(values)) if values else float("nan")


CSV_COLUMNS = [
    "iteration", "episode", "primitive", "how", "reward", "loss", "epsilon", "grasp_success", "target_grasped",
    "is_success", "num_motions", "grasp_success_rate", "decide_s", "act_s", "iteration_s",
]


def json_safe(data: dict[str, Any]) -> dict[str, Any]:
    """``data`` with NaN floats (an uncalibrated Q*_g) as ``None``, which JSON can hold."""
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in data.items()}
