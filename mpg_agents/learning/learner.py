"""The DQN learner of MPGNet for one training stage (paper Sections III-C and III-D).

One training loop, as Stable-Baselines3 splits collecting from training: a source of steps
feeds one learning step (:meth:`Learner.learn_from`). The steps come from actors
(:class:`~mpg_agents.learning.actors.Actor`: decide with the
:class:`~mpg_agents.acting.agent.MPGAgent`, Stage IV's forced grasp after its push budget;
explore, :mod:`mpg_agents.learning.exploration`; act through the one episode loop,
:func:`mpg_agents.acting.episode_loop.episode_steps`): with one actor the learner's own, in this
process (:func:`~mpg_agents.learning.learner_episodes.own_steps`); with ``actors > 1`` parallel
ones, each in its own env and process (:func:`~mpg_agents.learning.actor_feed.actor_steps`).
An iteration is one step of any of them: store it, and ``replay_ratio`` gradient steps
(:func:`mpg_agents.learning.td_step.td_step`; 1: one per iteration) with the stage's frozen
branches left out; count, log, save when due.
The stage is a :class:`~mpg_agents.learning.training_stages.TrainingStage`, the settings a
:class:`~mpg_agents.learning.train_config.TrainConfig`.

Q*_g (:mod:`mpg_agents.acting.grasp_threshold`): ``TrainConfig.q_star`` or the starting checkpoint's;
calibrated in the stage's scenes (``calibration_episodes``) or from its own greedy grasps at its
end (``calibrates_q_star``; :mod:`mpg_agents.learning.stage_calibration`). The weights carry it.

The state is saved every ``checkpoint_every`` iterations and on SIGINT/SIGTERM
(:mod:`mpg_agents.learning.run_state`): a killed run resumes with the same counters, replay,
weights, optimiser and generators; its interrupted episode restarts on the same scene. The log
(:mod:`mpg_agents.learning.train_log`) goes to TensorBoard and ``progress.csv``, rewound with
the state.

Optionally (off by default, the paper is pure RL): oracle transitions fill a fresh run's replay
(``TrainConfig.demonstration_episodes``, :mod:`mpg_agents.learning.demonstrations`); actions not
taken are tried in the simulation, undone and stored (``TrainingStage.grasp_trials``,
``move_trials``, ``rival_trials``, ``covered_grasp_trials``; :mod:`mpg_agents.learning.trials`; privileged).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Generator, Mapping
from contextlib import closing
from dataclasses import asdict
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from tqdm import tqdm

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_agents.acting.device import resolve_device
from mpg_agents.acting.grasp_threshold import from_header, starting_q_star
from mpg_agents.acting.q_function import MPGQFunction
from mpg_agents.acting.seeds import episode_seed
from mpg_agents.acting.weights import load_mpgnet_weights
from mpg_agents.learning.actor_feed import actor_steps
from mpg_agents.learning.actor_pool import check_actor_backend
from mpg_agents.learning.actors import ActorStep, build_agent, choose_action, make_explorer, make_training_env
from mpg_agents.learning.demonstrations import DEMONSTRATIONS_FILE, collect_demonstrations
from mpg_agents.learning.exploration import TakenAction, linear_epsilon
from mpg_agents.learning.learner_episodes import own_steps
from mpg_agents.learning.replay import PrioritizedHeightmapReplayBuffer
from mpg_agents.learning.run_folder import RunLock, check_resume, prepare_run_folder
from mpg_agents.learning.run_state import Counters, load_run_state, save_run_state, state_folder
from mpg_agents.learning.stage_calibration import calibrate_from_own_grasps, calibrate_if_due, calibrate_in_scenes
from mpg_agents.learning.stop_signal import StopFlag, StopRequested
from mpg_agents.learning.td_step import td_step
from mpg_agents.learning.train_config import TrainConfig, json_safe
from mpg_agents.learning.train_log import IterationRecord, TrainingLog
from mpg_agents.learning.training_stages import TrainingStage, stage_for_env
from mpg_agents.learning.trials import TRIAL_COUNTERS
from mpg_envs.files import write_text_whole
from mpg_envs.grid.primitive_specs import GRASP
from mpg_envs.simulation.objects import check_not_held_out


class Learner:
    """Trains an MPGNet on one stage; ``run()`` does the configured iterations (resumable).

    Args:
        config: the algorithm's settings.
        stage: what to train (a row of :data:`~mpg_agents.learning.training_stages.TRAINING_STAGES`,
            or :func:`~mpg_agents.learning.training_stages.stage_for_env` of an env id).
        out: the run folder.
        init: start from this MPGNet checkpoint (branches it lacks keep their initialisation).
        resume_anyway: resume a saved run whose settings differ (:func:`~mpg_agents.learning.run_folder.check_resume`).

    The run folder is locked from here to the end of ``run()`` (:class:`~mpg_agents.learning.run_folder.RunLock`).
    """

    def __init__(
        self,
        config: TrainConfig,
        stage: TrainingStage | str,
        out: str | Path,
        init: str | Path | None = None,
        log: Callable[[str], None] = print,
        resume_anyway: bool = False,
    ):
        self.config = config
        self.stage = stage_for_env(stage) if isinstance(stage, str) else stage
        self.steps = config.steps if config.steps is not None else self.stage.iterations
        # Before the run folder exists: a held-out object set is refused with nothing written.
        check_not_held_out(
            gym.spec(self.stage.env_id).kwargs.get("object_set", "blocks"), what=f"training on {self.stage.env_id}"
        )
        if config.actors > 1:
            check_actor_backend(config)  # Ray asked for and missing: refused before anything is written
        self.out = prepare_run_folder(out)
        self.lock = RunLock(self.out)  # before anything in the folder is read or written
        self.resume_anyway, self.log = resume_anyway, log
        torch.set_num_threads(config.torch_threads)
        # A young network's eval-mode activations go denormal and slow the CPU down 10x.
        torch.set_flush_denormal(True)
        self.device = resolve_device(config.device)  # networks and batches; the replay and the env stay on the host
        torch.manual_seed(config.seed)  # before the networks are built: the seed fixes their initial weights
        self.env = make_training_env(self.stage, config, self.objects_now(0), self.device)
        env: Any = self.env.unwrapped  # the MPG env (gym.Env does not declare its attributes)
        self.primitives: tuple[str, ...] = tuple(env.primitives)
        # The online agent, then the target network: their initial weights come from the seed in this order.
        self.policy = build_agent(self.stage, config, self.env).to(self.device)
        self.target_q = MPGQFunction(self.policy.net_config, self.policy.action_primitives, self.policy.q_net.mpgnet.geometry)
        self.target_q.to(self.device)
        self.target_q.set_training_mode(False)
        # What the agent acts with: the env's primitives it has a branch for.
        self.trainable = self.stage.trainable if self.stage.trainable is not None else self.policy.usable_primitives
        self.net = self.policy.q_net.mpgnet
        self.target = self.target_q.mpgnet
        self.optimizer = torch.optim.Adam(self.net.parameters(), lr=config.learning_rate, **config.optimizer_kwargs())
        header = load_mpgnet_weights(self.net, init, strict_branches=False) if init is not None else {}
        self.policy.set_q_star(starting_q_star(config.q_star, from_header(header)))
        for to, source in self.stage.branch_init:
            self.net.branches[to].load_state_dict(self.net.branches[source].state_dict())
        self.target.load_state_dict(self.net.state_dict())
        self.replay = PrioritizedHeightmapReplayBuffer(
            config.replay_capacity,
            env.observation_space,
            env.action_space,
            device=self.device,
            alpha=config.priority_alpha,
            seed=config.seed,
        )
        self.rng = np.random.default_rng(config.seed)
        self.explorer = make_explorer(self.policy, self.stage, self.primitives, self.rng, config)
        self.counters = Counters()
        self.calibration_env: gym.Env | None = None  # made at the first calibration in the stage's scenes
        self.stop = StopFlag()  # armed while run() learns
        self._log: TrainingLog | None = None
        self.resumed = False
        self._resume()

    def objects_now(self, iteration: int) -> int | None:
        """The scene's object count at ``iteration``: the fixed count, else the curriculum's."""
        if self.config.num_objects is not None:
            return self.config.num_objects
        return self.stage.objects_at(iteration / max(1, self.steps))

    def _saved_config(self) -> dict[str, Any]:
        return json_safe({**self.config.to_dict(), "stage": self.stage.to_dict()})

    def _resume(self) -> None:
        folder = state_folder(self.out)
        if folder is None:
            return
        saved = json.loads((folder / "config.json").read_text())
        changed = check_resume(self.out, saved, self._saved_config(), self.resume_anyway)
        self.resumed = True
        counters, _, q_star = load_run_state(
            folder, online=self.net, target=self.target, optimizer=self.optimizer, replay=self.replay, rng=self.rng
        )
        self.counters = Counters(**counters)
        if q_star is not None:  # the Q*_g the saved weights carry
            self.policy.set_q_star(q_star)
        self.log(
            f"resuming {self.out} at iteration {self.counters.iteration} (replay {self.replay.size()})"
            + (f" with changed settings: {'; '.join(changed)}" if changed else "")
        )

    def save_state(self) -> None:
        """Write weights and the full resumable state (atomically), the log's rows first."""
        if self._log is not None:
            self._log.sync()  # the state counts these rows: they must be on disk before it is
        save_run_state(
            self.out,
            online=self.net,
            target=self.target,
            q_star=self.policy.q_star,
            optimizer=self.optimizer,
            replay=self.replay,
            rng=self.rng,
            counters=asdict(self.counters),
            config=self._saved_config(),
        )
        self.policy.save_weights(self.out / "weights.safetensors", extra={"env_id": self.stage.env_id})

    # ------------------------------------------------------------------ loop
    def run(self) -> dict[str, Any]:
        """Train until the configured iterations are done; returns the final summary."""
        if self.stage.calibration_episodes and self.counters.calibrated_at < 0:  # the starting net
            calibrate_in_scenes(self, self.stage.calibration_episodes)
        if self.config.demonstration_episodes and not self.resumed:  # a fresh run: iteration 0, empty replay
            self.add_demonstrations()
        bar = tqdm(total=self.steps, initial=self.counters.iteration, desc=self.stage.name, unit="it", dynamic_ncols=True)
        try:
            with (
                self.stop,
                TrainingLog(self.out, self.counters.iteration) as self._log,
                closing(self.steps_to_learn()) as steps,
            ):
                for step in steps:
                    self.learn_from(step)
                    bar.update(1)
                    self.save_or_stop()
        finally:
            self._log = None
            bar.close()
        if self.stage.calibrate_every and self.counters.calibrated_at != self.counters.iteration:
            calibrate_in_scenes(self, self.stage.calibration_episodes)  # the weights ship with it
        if self.stage.calibrates_q_star:
            calibrate_from_own_grasps(self)
        c = self.counters
        summary = {"iteration": c.iteration, "episodes": c.episode}
        for switch, counters in TRIAL_COUNTERS.items():
            if getattr(self.stage, switch):
                summary.update({name: getattr(c, name) for name in counters})
        self.lock.release()
        return summary

    def save_or_stop(self) -> None:
        """Save every ``checkpoint_every`` iterations and at the end; on SIGINT/SIGTERM save and stop."""
        if (
            self.counters.iteration % self.config.checkpoint_every == 0
            or self.counters.iteration == self.steps
            or self.stop.asked
        ):
            self.save_state()
        if self.stop.asked:
            raise StopRequested()

    def add_demonstrations(self) -> None:
        """Fill the replay with the oracle's transitions on this stage's env and save the state
        (a resumed run keeps them and collects none). Every primitive the net has a branch for
        is kept, frozen ones too (:func:`td_step` leaves them out); the counters stay at 0."""
        stats = collect_demonstrations(
            self.env,
            self.config.demonstration_episodes,
            episode_seed(self.config.seed, 0, demonstration=True),
            self.policy.branches,
            self.store,
        )
        self.log(f"{self.stage.name}: {stats.summary()}")
        # The oracle's env steps count in the run's budget (mpg_agents.learning.env_steps).
        write_text_whole(self.out / DEMONSTRATIONS_FILE, json.dumps(stats.to_dict(), indent=1))
        self.save_state()

    def skipped_scene(self, k: int, error: Exception) -> None:
        self.counters.skipped_scenes += 1
        self.log(f"{self.stage.name}: episode {k} skipped, its seed gave no valid scene ({error})")

    def epsilon(self) -> float:
        cfg = self.config
        decay = cfg.epsilon_decay_steps if cfg.epsilon_decay_steps is not None else self.steps
        return linear_epsilon(self.counters.iteration, cfg.epsilon_start, cfg.epsilon_end, decay)

    def active_branches(self) -> tuple[str, ...]:
        """The branches learning this iteration (an alternating stage trains them in turn, a
        stage with a finish trains its ``finish_trainable`` alone at the end)."""
        return self.stage.branches_at(self.counters.iteration, self.steps, self.trainable)

    def steps_to_learn(self) -> Generator[ActorStep, None, None]:
        """The source of this run's steps: its own actor, or its config's parallel actors."""
        return actor_steps(self) if self.config.actors > 1 else own_steps(self)

    def learn_from(self, step: ActorStep) -> None:
        """The one learning step of an actor's step: its trials and the step stored, the gradient
        steps they earn (:meth:`learn_owed`), counted and logged; at its episode's end, the
        stage's periodic Q*_g calibration."""
        learning = time.perf_counter()
        c, choice = self.counters, step.choice
        if choice is None:
            raise ValueError(f"actor {step.actor} sent no step (episode {step.episode} skipped)")
        for next_obs, action, reward, terminated in step.trials:
            self.store(step.obs, next_obs, action, reward, terminated)
        for name, value in asdict(step.trial_counts).items():
            setattr(c, name, getattr(c, name) + value)
        self.store(step.obs, step.next_obs, choice.action, step.reward, step.terminated)
        loss = self.learn_owed(2 if step.trials else 1)  # the replay grew by 1 + len(trials) transitions
        self.record(
            choice, step.reward, step.info, loss, step.choose_seconds, step.step_seconds, learning, step.episode, step.done
        )
        if step.done:
            calibrate_if_due(self)

    def record(
        self,
        choice: TakenAction,
        reward: float,
        info: dict[str, Any],
        loss: float,
        t_decide: float,
        t_act: float,
        learning: float,
        episode: int,
        done: bool,
    ) -> None:
        """Count and log an iteration of episode ``episode`` (``learning``: when its learning began)."""
        c = self.counters
        c.iteration += 1
        if choice.primitive == GRASP:
            c.window_grasps += 1
            c.window_target_grasps += int(info["target_grasped"])
            if info["target_grasped"] and choice.chosen_by == "greedy" and math.isfinite(choice.q_value):
                c.successful_grasp_q = (c.successful_grasp_q + [choice.q_value])[-200:]
        rate = None
        if c.iteration % self.config.window == 0 and c.window_grasps:
            rate = c.window_target_grasps / c.window_grasps
            c.window_grasps = c.window_target_grasps = 0
        assert self._log is not None
        self._log.record(
            IterationRecord(
                c.iteration,
                episode,
                choice.primitive,
                choice.chosen_by,
                reward,
                loss,
                self.epsilon(),
                info,
                t_decide,
                t_act,
                t_decide + t_act + time.perf_counter() - learning,
                rate,
            )
        )
        if done:
            self._log.episode_end(c.iteration, info)

    def store(self, obs: Mapping[str, Any], next_obs: Mapping[str, Any], action: int, reward: float, terminated: bool) -> None:
        """Add one transition to the replay (batch of one; a truncation is no terminal state)."""
        self.replay.add(
            {k: v[None] for k, v in obs.items()},
            {k: v[None] for k, v in next_obs.items()},
            np.array([[action]]),
            np.array([reward], dtype=np.float32),
            np.array([terminated], dtype=np.float32),
            [{}],
        )

    def act(self, obs: Mapping[str, Any]) -> TakenAction:
        """The action to take: the policy's decision, then exploration and the training aids."""
        c = self.counters
        return choose_action(
            self.policy, self.explorer, self.stage, obs, self.epsilon(), c.pushes_in_episode, c.failed_grasps_in_a_row
        )

    def learn_owed(self, units: int) -> float:
        """The gradient steps ``units`` env steps earn at ``replay_ratio`` (the fraction carried
        over in the counters); returns the first step's loss (NaN when none was taken)."""
        c = self.counters
        c.replay_credit += self.config.replay_ratio * units
        owed = int(c.replay_credit + 1e-9)
        c.replay_credit = max(0.0, c.replay_credit - owed)
        losses = [self.learn() for _ in range(owed)]
        return losses[0] if losses else float("nan")

    def learn(self) -> float:
        """One gradient step on a prioritised batch; returns the loss (NaN when nothing learnt)."""
        if self.replay.size() == 0:
            return float("nan")
        batch = self.replay.sample(min(self.config.batch_size, self.replay.size()))
        result = td_step(
            self.policy.q_net,
            self.target_q,
            self.optimizer,
            batch,
            self.config.step_config(),
            self.active_branches(),
            self.replay,
        )
        if result.trained:
            self.counters.gradient_steps += 1
            if self.counters.gradient_steps % self.config.target_update_every == 0:
                self.target.load_state_dict(self.net.state_dict())
        return result.loss
