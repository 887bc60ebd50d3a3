"""The paper's training stages as data (Section III-C): one :class:`TrainingStage` per stage.

I target-agnostic grasping -> II target-oriented grasping (then Q*_g is calibrated) -> III
moving (the Stage II grasp net scores states; objects grow from 2) -> IV pushing (grasp and
move frozen; a grasp ends the episode after the push budget) -> V joint training (the three
nets in turn). The pipeline, the learner and ``mpg-train`` read this table; the ablations and
the learned baselines are changes of it (:mod:`mpg_agents.learning.stage_variants`).

The envs' own differences (scene, rewards, motion cap) are in :mod:`mpg_envs.tasks.stages`; this
table holds only how the agent trains on them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

from mpg_agents.acting.calibration_quantile import CALIBRATION_QUANTILE, check_quantile
from mpg_agents.acting.coordination import check_coordination
from mpg_agents.learning.training_objects import OBS_MODES, STAGE_ENV_OPTIONS, object_set_entries, stage_env_config
from mpg_envs.grid.actions import check_primitives
from mpg_envs.grid.grasp_geometry import GRASP_ROTATIONS
from mpg_envs.grid.primitive_specs import GRASP, MOVE, PUSH
from mpg_envs.perception.visual_randomization import VisualRandomization
from mpg_envs.scenes.arranged import ArrangedScenes
from mpg_envs.settings_fields import check_known_fields
from mpg_envs.tasks.rewards import RewardConfig

MAX_MOVE_TRIALS = 8
"""The most move trials per move (each costs about a move's simulation)."""


@dataclass(frozen=True)
class TrainingStage:
    """How one training stage trains.

    Attributes:
        name: the stage's name (also its run folder, ``out/<name>/``).
        env_id: the env it trains on.
        trainable: the branches that learn (``None``: the env's primitives); the rest are frozen.
        objects: curriculum ``(start, end)``: objects grow linearly from ``start`` to ``end``
            over the stage; ``None`` keeps the env's count.
        alternate_every: train the trainable nets in turn, switching every this many
            iterations (0: all together).
        alternate_shares: ``((branch, turns), ...)``: in each round of the alternation this
            branch trains ``turns`` turns of ``alternate_every`` iterations in a row (the others
            one), e.g. ``(("grasp", 3),)`` gives the grasp net 3/5 of a three-net stage's steps.
        finish_iterations: the stage's last this many iterations train only ``finish_trainable``
            (0: no finish), e.g. the grasp net alone after the three nets' alternation.
        finish_trainable: the branches that learn in the finish.
        coordination: how the primitive is chosen (:mod:`mpg_agents.acting.coordination`).
        calibrates_q_star: at its end, the stage estimates Q*_g from the Q of its own recent
            greedy grasps that took the target (at ``calibration_quantile``;
            :mod:`mpg_agents.acting.grasp_threshold`).
        calibration_episodes: before it trains, the stage calibrates Q*_g again in its own
            scenes from the Q of the greedy grasps that take the target in this many
            grasp-only episodes of the starting net, no learning (0: keep the Q*_g it is given).
            Q*_g from isolated targets (Stage II) sits above what a sure grasp in clutter
            scores, and the workflow then pushes instead of grasping.
        calibration_quantile: which quantile of those grasps' Q (either kind) becomes Q*_g:
            0.5, the median (where the Q of successful grasps settles, the paper's reading); a
            lower one lets the workflow take more of the grasps that do succeed.
        calibrate_every: with ``calibration_episodes``, calibrate again at the first episode
            end after every this many iterations and once at the stage's end, so Q*_g follows
            the grasp net's Q scale while it learns (0: only before training). A fixed Q*_g
            that the learning grasp Q drifts below turns the workflow into pushing.
        uses_discriminator: the envs score states with the discriminator, the grasp net of the
            stage that ``calibrates_q_star``.
        push_budget: after this many pushes in an episode the grasp is forced (``None``: never).
        iterations: default number of training iterations.
        branches: the nets the agent has and acts with (``None``: all three); a baseline
            without move is ``("push", "grasp")``. Its checkpoint holds only these.
        branch_init: ``((to, from), ...)``: at the stage's start, branch ``to`` is copied from
            branch ``from`` of the starting weights, e.g. ``(("move", "grasp"),)``: a move is a
            grasp of the occluder, carried away, so the move net starts as the grasp net.
        reward: ``((field, value), ...)`` (a TOML table in a config) of
            :class:`~mpg_envs.tasks.rewards.RewardConfig` fields that this stage's training envs
            set, e.g. ``{"move_needs_lift": True}``; empty: the paper's rewards.
        grasp_trials: each grasp the stage takes is also tried at this many other gripper
            orientations at the same pixel (drawn from the other ``GRASP_ROTATIONS - 1``, each
            in either of its two rotations), in the simulation and undone
            (:meth:`~mpg_envs.tasks.env.MPGEnv.try_step`); those transitions go into the replay, with
            one more gradient step per grasp. A grasp in clutter is decided by its angle, and
            one executed grasp labels one angle. Privileged (a simulator's counterfactual, like
            demonstrations, not the paper's pure RL); 0: off.
        move_trials: each move the stage takes is also tried at the move net's this many next-best
            places (:mod:`mpg_agents.learning.trials`), in the simulation and undone, and stored,
            with one more gradient step per move. Privileged like ``grasp_trials``; 0: off.
        rival_trials: while the target is covered, each move the stage takes is also tried as the
            push net's best push, and each push as the move net's best move, in the simulation
            and undone, and stored (one more gradient step): every uncovering step labels the
            primitive it did not take, so a rule weighing the two
            (``coordination = "uncover_max_q"``, with ``reward = {push_uncovers = true}``)
            learns where a push does the move's work. Privileged like ``grasp_trials``; off by default.
        covered_grasp_trials: while the target is covered, each move or push the stage takes is
            also tried as the grasp net's best grasp, in the simulation and undone, and stored
            (one more gradient step): the grasp net learns which covered targets it can take
            already, which the workflow (never grasping a covered target) does not teach it and
            a rule grasping before uncovering (``coordination = "grasp_first_uncover_max_q"``)
            needs. Privileged like ``grasp_trials``; off by default.
        env_options: ``((keyword, value), ...)`` (a TOML table) of ``gym.make`` keywords for the
            stage's training envs, of :data:`STAGE_ENV_OPTIONS`: ``object_set`` (a set name, or a
            list of sets pooled into one, each ``"name"`` or ``"name:seed"``, e.g.
            ``["blocks", "procedural:0", "procedural:1"]``; see :func:`object_set_entries`),
            ``visual_randomization`` and ``arranged`` (the env options), ``obs_mode`` and ``config`` (a table of
            EnvConfig fields other than ``reward``, e.g. ``scene_tries``). The object count and the
            rewards stay the stage's own (``objects``, ``reward``); empty: the env's defaults.
    """

    name: str
    env_id: str
    trainable: tuple[str, ...] | None = None
    objects: tuple[int, int] | None = None
    alternate_every: int = 0
    alternate_shares: tuple[tuple[str, int], ...] = ()
    finish_iterations: int = 0
    finish_trainable: tuple[str, ...] = ()
    coordination: str = "workflow"
    calibrates_q_star: bool = False
    calibration_episodes: int = 0
    calibration_quantile: float = CALIBRATION_QUANTILE
    calibrate_every: int = 0
    uses_discriminator: bool = False
    push_budget: int | None = None
    iterations: int = 1000
    branch_init: tuple[tuple[str, str], ...] = ()
    branches: tuple[str, ...] | None = None
    reward: tuple[tuple[str, Any], ...] = ()
    grasp_trials: int = 0
    move_trials: int = 0
    rival_trials: bool = False
    covered_grasp_trials: bool = False
    env_options: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        options = dict(
            self.env_options.items() if isinstance(self.env_options, Mapping) else (tuple(p) for p in self.env_options)
        )
        unknown = sorted(set(options) - set(STAGE_ENV_OPTIONS))
        if unknown:
            raise ValueError(f"stage {self.name}: env_options takes {list(STAGE_ENV_OPTIONS)}, got {unknown}")
        if "object_set" in options:
            entries = object_set_entries(options["object_set"], f"stage {self.name}")
            options["object_set"] = (
                entries[0][0]
                if len(entries) == 1 and entries[0][1] is None
                else tuple(name if seed is None else f"{name}:{seed}" for name, seed in entries)
            )
        if "visual_randomization" in options:
            VisualRandomization.from_option(options["visual_randomization"])  # raises naming what is wrong
        if "arranged" in options:
            ArrangedScenes.from_option(options["arranged"])  # raises naming what is wrong
        if "config" in options:
            stage_env_config(options)  # raises naming what is wrong
        if options.get("obs_mode", "raycast") not in OBS_MODES:
            raise ValueError(
                f"stage {self.name}: env_options obs_mode must be one of {list(OBS_MODES)}, got {options['obs_mode']!r}"
            )
        object.__setattr__(self, "env_options", tuple(sorted(options.items())))
        for name in ("rival_trials", "covered_grasp_trials"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"stage {self.name}: {name} must be true or false, got {getattr(self, name)!r}")
        for name, most in (("grasp_trials", GRASP_ROTATIONS - 1), ("move_trials", MAX_MOVE_TRIALS)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= most:
                raise ValueError(f"stage {self.name}: {name} must be an integer in 0..{most}, got {value!r}")
        pairs = tuple(self.reward.items()) if isinstance(self.reward, Mapping) else tuple(tuple(p) for p in self.reward)
        known = {f.name for f in fields(RewardConfig)}
        for pair in pairs:
            if len(pair) != 2 or pair[0] not in known:
                raise ValueError(
                    f"stage {self.name}: reward takes RewardConfig fields {sorted(known)} with values, got {pair}"
                )
        object.__setattr__(self, "reward", tuple(sorted(pairs)))
        if self.branches is not None:
            object.__setattr__(self, "branches", check_primitives(self.branches))
            outside = sorted((set(self.trainable or ()) | set(self.finish_trainable)) - set(self.branches))
            if outside:
                raise ValueError(f"stage {self.name}: trains {outside}, which are not among its branches {self.branches}")
        pairs = tuple(tuple(pair) for pair in self.branch_init)
        for pair in pairs:
            if len(pair) != 2 or pair[0] == pair[1]:
                raise ValueError(f"stage {self.name}: branch_init takes (to, from) pairs of two primitives, got {pair}")
            for primitive in pair:
                check_primitives((primitive,))
        object.__setattr__(self, "branch_init", pairs)
        shares = tuple((str(branch), int(turns)) for branch, turns in self.alternate_shares)
        for branch, turns in shares:
            check_primitives((branch,))
            if turns < 1:
                raise ValueError(f"stage {self.name}: alternate_shares gives {branch!r} {turns} turns; need >= 1")
        object.__setattr__(self, "alternate_shares", shares)
        if self.finish_trainable:
            object.__setattr__(self, "finish_trainable", check_primitives(self.finish_trainable))
        if not 0 <= self.finish_iterations < self.iterations:
            raise ValueError(
                f"stage {self.name}: finish_iterations must be in [0, "
                f"iterations={self.iterations}), got {self.finish_iterations}"
            )
        if bool(self.finish_iterations) != bool(self.finish_trainable):
            raise ValueError(
                f"stage {self.name}: finish_iterations and finish_trainable go "
                f"together (got {self.finish_iterations}, {self.finish_trainable})"
            )
        if self.trainable is not None:
            object.__setattr__(self, "trainable", check_primitives(self.trainable))
        if self.objects is not None:
            start, end = (int(v) for v in self.objects)
            if not 1 <= start <= end:
                raise ValueError(f"stage {self.name}: objects must be (start, end) with 1 <= start <= end, got {self.objects}")
            object.__setattr__(self, "objects", (start, end))
        check_coordination(self.coordination)
        if self.calibration_episodes < 0:
            raise ValueError(f"stage {self.name}: calibration_episodes must be >= 0, got {self.calibration_episodes}")
        check_quantile(self.calibration_quantile, f"stage {self.name}: calibration_quantile")
        if self.calibrate_every < 0 or (self.calibrate_every and not self.calibration_episodes):
            raise ValueError(
                f"stage {self.name}: calibrate_every must be 0, or >= 1 with calibration_episodes, got {self.calibrate_every}"
            )
        if self.calibration_episodes and self.calibrates_q_star:
            raise ValueError(f"stage {self.name}: calibrates_q_star and calibration_episodes both set Q*_g; choose one")
        if self.alternate_every < 0 or self.iterations < 1:
            raise ValueError(f"stage {self.name}: need alternate_every >= 0 and iterations >= 1")
        if self.push_budget is not None and self.push_budget < 0:
            raise ValueError(f"stage {self.name}: push_budget must be None or >= 0, got {self.push_budget}")

    def branches_at(self, iteration: int, steps: int, trainable: tuple[str, ...]) -> tuple[str, ...]:
        """The branches that learn at ``iteration`` (0-based) of a run of ``steps`` iterations
        whose trainable branches are ``trainable``: the finish's, else the alternation's turn."""
        if self.finish_iterations and iteration >= steps - self.finish_iterations:
            return self.finish_trainable
        if self.alternate_every <= 0:
            return trainable
        shares = dict(self.alternate_shares)
        rounds = [branch for branch in trainable for _ in range(shares.get(branch, 1))]
        return (rounds[(iteration // self.alternate_every) % len(rounds)],)

    @property
    def reads_q_star(self) -> bool:
        """Whether this stage's coordination ever consults Q*_g: not by the largest Q, not with
        one branch."""
        return self.coordination != "max_q" and (self.branches is None or len(self.branches) > 1)

    def reward_config(self, base: RewardConfig = RewardConfig()) -> RewardConfig:
        """``base`` with this stage's :attr:`reward` settings."""
        return replace(base, **dict(self.reward))

    def objects_at(self, fraction: float) -> int | None:
        """The curriculum's object count after ``fraction`` (0..1) of the stage; ``None``: the env's."""
        if self.objects is None:
            return None
        start, end = self.objects
        return int(round(start + min(1.0, max(0.0, fraction)) * (end - start)))

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["branch_init"] = [list(pair) for pair in self.branch_init]
        data["alternate_shares"] = [list(pair) for pair in self.alternate_shares]
        data["reward"] = dict(self.reward)
        data["env_options"] = {k: list(v) if isinstance(v, tuple) else v for k, v in self.env_options}
        return {k: list(v) if isinstance(v, tuple) else v for k, v in data.items()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrainingStage:
        check_known_fields(cls, data, "training stage settings")
        kwargs: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**kwargs)


TRAINING_STAGES: tuple[TrainingStage, ...] = (
    TrainingStage("Stage1", "MPG-Stage1-v0", trainable=(GRASP,), iterations=500),
    TrainingStage("Stage2", "MPG-Stage2-v0", trainable=(GRASP,), calibrates_q_star=True, iterations=1000),
    TrainingStage("Stage3", "MPG-Stage3-v0", trainable=(MOVE,), objects=(2, 4), uses_discriminator=True, iterations=600),
    TrainingStage("Stage4", "MPG-Stage4-v0", trainable=(PUSH,), uses_discriminator=True, push_budget=5, iterations=600),
    TrainingStage(
        "Stage5",
        "MPG-Stage5-v0",
        trainable=(MOVE, PUSH, GRASP),
        alternate_every=50,
        uses_discriminator=True,
        iterations=1500,
    ),
)
"""The paper's five stages, in order."""


def stage_for_env(env_id: str, stages: Sequence[TrainingStage] = TRAINING_STAGES) -> TrainingStage:
    """The stage that trains on ``env_id``; an env no stage names (e.g. ``MPG-Occluded-v0``)
    trains all its primitives together, with no curriculum, budget or discriminator.

    Raises:
        ValueError: ``env_id`` is a paper stage's own env, but ``stages`` (a config) moved that
            stage to another env: the stage's settings would otherwise be dropped without a word.
    """
    for stage in stages:
        if stage.env_id == env_id:
            return stage
    paper_stage = next((s.name for s in TRAINING_STAGES if s.env_id == env_id), None)
    moved = next((s for s in stages if s.name == paper_stage), None)  # no stage of ``stages`` trains on env_id
    if moved is not None:
        raise ValueError(
            f"--env {env_id}: the config moves {moved.name} to {moved.env_id}; "
            f"give --env {moved.env_id} to train {moved.name} with its settings"
        )
    return TrainingStage(env_id, env_id)


def select_stages(stages: Sequence[TrainingStage], which: Sequence[str]) -> tuple[TrainingStage, ...]:
    """The stages named in ``which``: stage names (``Stage2``) or 1-based positions (``2``)."""
    by_name = {s.name: s for s in stages}
    chosen = []
    for item in which:
        item = str(item).strip()
        if item in by_name:
            chosen.append(by_name[item])
        elif item.isdigit() and 1 <= int(item) <= len(stages):
            chosen.append(stages[int(item) - 1])
        else:
            raise ValueError(f"unknown stage {item!r}; valid: {', '.join(by_name)} or 1..{len(stages)}")
    return tuple(chosen)


def with_overrides(stages: Sequence[TrainingStage], overrides: Mapping[str, Mapping[str, Any]]) -> tuple[TrainingStage, ...]:
    """``stages`` with fields replaced per stage name, e.g. ``{"Stage3": {"objects": [2, 3]}}``."""
    unknown = sorted(set(overrides) - {s.name for s in stages})
    if unknown:
        raise ValueError(f"overrides for unknown stages {unknown}; valid: {[s.name for s in stages]}")
    return tuple(TrainingStage.from_dict({**s.to_dict(), **overrides[s.name]}) if s.name in overrides else s for s in stages)
