"""``MPGEnv``: one Gymnasium env class; each registered id is a :class:`StageSpec`.

Life of a step, as named hooks: decode the pixel-wise action, run the primitive in the world,
observe (heightmaps, target mask, occlusion, visible fraction), ``evaluate`` what the step did
(a :class:`~mpg_envs.tasks.step_evaluation.StepEvaluation`), ``step_reward`` it, and decide the end
(:func:`~mpg_envs.tasks.stages.episode_end`). A reset's scene comes from ``_initialize_episode``: a
scene file, the shipped test set of the seed, or a fresh drop (:mod:`mpg_envs.tasks.scene_source`).
The world, the primitives executor and the views of the episode are one public handle,
``env.sim`` (:class:`~mpg_envs.tasks.episode_sim.EpisodeSim`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from mpg_envs.grid.actions import PixelActionSpace
from mpg_envs.grid.primitive_specs import primitive_spec
from mpg_envs.perception.render import OverviewRenderer, render_overview
from mpg_envs.perception.visual_randomization import EpisodeVisuals, VisualRandomization, episode_visuals
from mpg_envs.scenes.arranged import ArrangedScenes
from mpg_envs.scenes.generators import InvalidSceneError
from mpg_envs.scenes.scene_file import SceneFile
from mpg_envs.scenes.scene_loading import scene_of
from mpg_envs.simulation.objects import ObjectAsset
from mpg_envs.simulation.primitives import PrimitiveResult
from mpg_envs.simulation.world import World
from mpg_envs.tasks.config import OBS_MODES, EnvConfig, check_camera_config, config_of, object_assets, observation_space
from mpg_envs.tasks.env_keywords import (
    GraspScorer,
    check_grasp_scorer,
    check_max_motions,
    check_num_objects,
    check_obs_mode,
    check_render_mode,
    check_use_test_set,
    check_visible_range,
    check_wrong_grasp,
    stage_of,
)
from mpg_envs.tasks.episode_sim import EpisodeSim
from mpg_envs.tasks.scene_source import RESET_OPTIONS, SceneRequest, check_test_scene, checked_reset_options, start_scene
from mpg_envs.tasks.stages import END_REASONS, StageSpec, episode_end
from mpg_envs.tasks.step_evaluation import StepEvaluation, action_info, judge_step
from mpg_envs.tasks.target_spec import SIMULATOR_KEYS, TargetNaming, target_observation_space

__all__ = [
    "END_REASONS",
    "OBS_MODES",
    "RESET_OPTIONS",
    "EnvConfig",
    "InvalidSceneError",
    "MPGEnv",
    "StepEvaluation",
    "observation_space",
]


class MPGEnv(gym.Env):
    """Target-oriented grasping in clutter with pixel-wise move/push/grasp actions.

    Attributes (read-only for callers; the agents package relies on them):
        stage: the :class:`~mpg_envs.tasks.stages.StageSpec` this env runs (its ``name``,
            ``env_id``, ``primitives``, ``end_after_grasp``, ``mask_all_objects``, ...).
        num_objects: objects dropped at every reset (the stage's default unless given).
        primitives: the primitive names this env accepts, in action-code order.
        max_motions: the motion cap; an episode is truncated when it is reached.
        num_motions: motions taken so far in the current episode.
        target: index of the target object in the world (``None`` in Stage 1, where every
            object is a target).
        world: the :class:`~mpg_envs.simulation.world.World` of the current episode (``None`` before
            the first reset; ``sim.world``).
        sim: the episode's simulation (:class:`~mpg_envs.tasks.episode_sim.EpisodeSim`): world,
            primitives executor (``sim.executor``), heightmaps and target views, try-and-undo;
            what scene making, the oracle and diagnostics work on.
        visuals: this episode's drawn visual randomization (``None`` when off; ``sim.visuals``).

    Keywords beyond the stage: ``wrong_grasp`` (``"remove"``, the paper's protocol, or ``"fail"``: strict
    retrieval, a mis-pick ends the episode), ``visible_range`` (a band of the target's visible fraction at
    reset), ``use_test_set`` (True or False: load the shipped scenes of the test seeds, or generate every scene),
    ``arranged`` (a share of generated resets starting from a drawn arrangement of blocks, with its own
    object count and start: :class:`~mpg_envs.scenes.arranged.ArrangedScenes`; off by default),
    ``target_spec`` (how the policy is told the target, :mod:`mpg_envs.tasks.target_spec`).

    Reset: a generated scene has exactly ``num_objects`` objects, all resting inside the
    workspace, and meets the start condition (the stage's occlusion or surround, the visible
    band); else :class:`~mpg_envs.scenes.generators.InvalidSceneError`, never a lesser scene.
    ``reset(options=...)`` takes ``scene`` (a scene file, ours or a peer's, or a
    :class:`~mpg_envs.scenes.scene_io.SceneFile`), ``mesh_dir`` (meshes for a peer's file),
    ``drop_outside`` (leave out, with a warning, the file's objects outside the workspace
    instead of raising :class:`~mpg_envs.scenes.scene_io.SceneFileError`) and ``num_objects`` (this
    episode's count). Reset's ``info`` has ``objects_left``, ``occluded``,
    ``visible_fraction``, ``target``, ``num_motions``, ``is_success`` and, with
    ``visual_randomization`` on, the episode's drawn values; a step's also
    ``end_reason`` (``None`` until the last step, then one of :data:`END_REASONS`). ``step()`` after
    the episode ended, before the first ``reset()``, after a ``reset()`` that raised or after
    ``close()`` raises ``RuntimeError`` until the next ``reset()`` that completes.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 2}
    action_space: PixelActionSpace  # gym.Env declares a Space

    def __init__(
        self,
        stage: str | StageSpec = "Stage5",
        num_objects: int | None = None,
        obs_mode: str = "raycast",
        object_set: str | Sequence[ObjectAsset] = "blocks",
        max_motions: int | None = None,
        grasp_scorer: GraspScorer | None = None,
        render_mode: str | None = None,
        config: EnvConfig | dict[str, Any] = EnvConfig(),
        camera_config: Any = None,
        wrong_grasp: str | None = None,
        visible_range: tuple[float, float] | None = None,
        use_test_set: bool = True,
        visual_randomization: Any = None,
        arranged: Any = None,
        target_spec: str = "mask",
    ):
        config = config_of(config)  # a dict of EnvConfig fields too (a registered track's)
        # Each keyword checked in this order (mpg_envs.tasks.env_keywords): the first wrong one is named.
        self.stage: StageSpec = stage_of(stage)
        stage_spec = self.stage
        self.num_objects = check_num_objects(stage_spec.num_objects if num_objects is None else num_objects, stage_spec)
        self.default_num_objects = self.num_objects
        self.mis_pick_rule = check_wrong_grasp(wrong_grasp, stage_spec)  # the keyword wrong_grasp: the rule
        self.visible_range = check_visible_range(visible_range, stage_spec)
        self.use_test_set = check_use_test_set(use_test_set)
        self.max_motions = check_max_motions(max_motions, stage_spec)
        self.obs_mode = check_obs_mode(obs_mode)
        self.render_mode = check_render_mode(render_mode, self.metadata["render_modes"])
        self.grasp_scorer = check_grasp_scorer(grasp_scorer)
        self.config = config
        self.camera_config = check_camera_config(camera_config)
        self.visual_randomization = VisualRandomization.from_option(visual_randomization)  # None: off
        self.arranged = ArrangedScenes.from_option(arranged)  # None: off
        self.object_set = object_assets(object_set, config.object_set_seed)  # a name, a folder or assets
        self._object_set_name = str(object_set) if isinstance(object_set, (str, Path)) else "custom"
        self.primitives = stage_spec.primitives
        size = config.workspace.shape
        self.action_space = PixelActionSpace(self.primitives, size=size[0])
        self.naming = TargetNaming(target_spec, stage_spec, config, obs_mode, camera_config, self.visual_randomization)
        self.target_spec = self.naming.spec
        self.observation_space = target_observation_space(self.target_spec, config.workspace)
        # The arm's visual meshes matter only to pictures: leave them out unless something renders.
        visual = render_mode is not None or obs_mode == "camera"
        self.sim = EpisodeSim(
            config,
            obs_mode=obs_mode,
            camera_config=camera_config,
            robot_visual=visual,
            mask_all_objects=stage_spec.mask_all_objects,
        )
        self._renderer: OverviewRenderer | None = None
        self.target: int | None = None
        self._obs: dict[str, np.ndarray] | None = None
        self._score: tuple[dict, float] | None = None  # (observation, its grasp score)
        self._visible: float | None = None  # the target's visible fraction in the last observation
        self.num_motions = 0
        self._ended: str | None = "call reset() before step()"  # why step() may not run now (None: it may)

    # ------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        # A reset that raises leaves a half-built world: no episode until this one completes.
        self._ended = "the last reset() raised; call reset() before step()"
        self._obs = self._score = self.target = None
        self.num_motions = 0
        super().reset(seed=seed)
        options = checked_reset_options(options)
        self.num_objects = check_num_objects(options.get("num_objects", self.default_num_objects), self.stage)
        self.sim.visuals = None  # a drawn scene's start condition is judged unrandomized: the same scenes either way
        self._initialize_episode(seed, options)
        self.sim.visuals = episode_visuals(self.visual_randomization, seed, self.np_random)
        self.naming.start_episode(self.sim, self.target, seed, self.np_random)  # exemplar: colours and query
        obs = self._observe()
        if self._test_seed is not None:  # a scene changed in its test set's file is refused (check_test_scene)
            check_test_scene(self.sim, self.scene_request, self._test_seed, self.target, self._visible)
        info = {**self._reset_info(obs), **self.naming.reset_info()}
        self._obs, self._ended = obs, None  # the episode is open only now
        return self._copy_obs(self.naming.public(obs)), info

    def step(self, action):
        if self._ended is not None:
            raise RuntimeError(self._ended)
        primitive, rotation, row, col = self.action_space.decode(action)
        before, executor = self._obs, self.sim.executor
        assert before is not None and executor is not None  # an open episode has both
        score_before = None if primitive_spec(primitive).retrieves else self._grasp_score(before)
        visible_before = self._visible
        result = executor.execute(primitive, rotation, row, col, before["depth"], self.target)
        self.num_motions += 1
        sim_warnings = self._check_physics()
        self._obs = self._observe()
        evaluation = self.evaluate(primitive, before, result, score_before, visible_before)
        reward = self.step_reward(evaluation)
        terminated, truncated, end_reason = episode_end(
            self.stage,
            is_success=evaluation.is_success,
            target_out=evaluation.target_out,
            move_success=evaluation.outcome.move_success,
            primitive=primitive,
            num_motions=self.num_motions,
            max_motions=self.max_motions,
            wrong_object=evaluation.ends_wrong_object,
        )
        info = {**action_info(primitive, rotation, row, col, result), **evaluation.info()}
        info.update(num_motions=self.num_motions, sim_warnings=sim_warnings, end_reason=end_reason)
        info.update(self.naming.step_info(evaluation.mis_pick, result.grasped_object))
        self._ended = None if end_reason is None else f"the episode has ended ({end_reason}); call reset() before step()"
        return self._copy_obs(self.naming.public(self._obs)), reward, bool(terminated), bool(truncated), info

    # ------------------------------------------------------------ task hooks
    def _initialize_episode(self, seed: int | None, options: dict[str, Any]) -> None:
        """Build this episode's world and target in ``sim``: a scene file, else the shipped
        test set's scene of ``seed``, else objects dropped afresh (:func:`mpg_envs.tasks.scene_source.start_scene`)."""
        self._test_seed: int | None = None  # the seed of a shipped test scene built here
        self.sim.initialize_episode(self.np_random)
        # reset() checks a test set's scene against its set once it has observed it
        self.target, self._test_seed = start_scene(self.sim, self.scene_request, seed, options, self.arranged)

    def evaluate(
        self,
        primitive: str,
        before: dict[str, np.ndarray],
        result: PrimitiveResult,
        score_before: float | None,
        visible_before: float | None = None,
    ) -> StepEvaluation:
        """What the step did, judged on the new state (success, mis-pick, move success,
        occlusion, visibility and its gain over ``visible_before``, change); the reward and
        the episode's end are read off it (:func:`~mpg_envs.tasks.step_evaluation.judge_step`)."""
        obs = self._obs
        assert obs is not None  # the step's new observation
        return judge_step(
            primitive,
            before,
            obs,
            result,
            self._live_world(),
            self.target,
            mask_all_objects=self.stage.mask_all_objects,
            mis_pick_rule=self.mis_pick_rule,
            change=self.config.change,
            grasp_gain=0.0 if score_before is None else self._grasp_score(obs) - score_before,
            visible_before=visible_before,
            visible=self._visible,
        )

    def step_reward(self, evaluation: StepEvaluation) -> float:
        """The stage's reward of the step; under strict retrieval a mis-pick earns
        ``RewardConfig.wrong_object`` instead."""
        if evaluation.ends_wrong_object:
            return float(self.config.reward.wrong_object)
        return float(self.stage.reward(evaluation.outcome, self.config.reward))

    def try_step(self, action):
        """What ``step(action)`` returns, with the episode then put back exactly as it was.

        A counterfactual that only a simulator can give (the world, the motion count, the
        last observation and the noise generator are restored; MuJoCo is deterministic, so
        ``step(action)`` afterwards returns the same). Trainers may use it to label actions
        they did not take; a policy under evaluation must not.
        """
        if self._ended is not None:
            raise RuntimeError(self._ended.replace("step()", "try_step()"))
        saved = (self.num_motions, self._obs, self._score, self._visible, self._ended)
        with self.sim.trial():  # the world and the generator
            try:
                return self.step(action)
            finally:
                self.num_motions, self._obs, self._score, self._visible, self._ended = saved

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self._obs is None:  # before the first reset, or after one that raised
            raise RuntimeError("call reset() before render()")
        world = self._live_world()
        if self._renderer is None or self._renderer.model is not world.model:
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = render_overview(world.model)
        return self._renderer.render(world.data)

    def close(self):
        self._ended = "the env is closed; call reset() to start a new episode before step()"
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        self.sim.close()
        self.naming.close()

    # ------------------------------------------------------------ helpers
    @property
    def target_index(self) -> int | None:
        """Index of the target object in ``world`` (``None`` in Stage I)."""
        return self.target

    @property
    def wrong_grasp(self) -> str:
        """What a mis-pick does (the keyword ``wrong_grasp``: ``"remove"`` or ``"fail"``;
        ``mis_pick_rule``)."""
        return self.mis_pick_rule

    @property
    def scene_request(self) -> SceneRequest:
        """What this env's resets ask of a scene (stage, object count and set, visible band,
        settings): what :mod:`mpg_envs.tasks.scene_source` drops or looks up."""
        return SceneRequest(
            self.stage,
            self.num_objects,
            self.object_set,
            self._object_set_name,
            self.visible_range,
            self.config,
            self.use_test_set,
        )

    @property
    def world(self) -> World | None:
        """The current episode's world (``sim.world``; ``None`` before the first reset)."""
        return self.sim.world

    @property
    def visuals(self) -> EpisodeVisuals | None:
        """This episode's drawn visual randomization (``sim.visuals``; ``None`` when off)."""
        return self.sim.visuals

    @property
    def last_observation(self) -> dict[str, np.ndarray] | None:
        """A copy of the last observation returned by ``reset`` or ``step`` (``None`` before
        the first reset)."""
        return None if self._obs is None else self._copy_obs(self.naming.public(self._obs))

    def current_scene(self) -> SceneFile:
        """The current scene (every object's asset, pose and state, the target), as
        :func:`mpg_envs.scenes.scene_io.save_scene` writes it."""
        if self._obs is None:  # before the first reset, or after one that raised
            raise RuntimeError("call reset() before current_scene()")
        return scene_of(self._live_world(), self.target, self.stage.name, self.config.object_set_seed)

    def _live_world(self) -> World:
        """The episode's world (``sim.world``), which a reset builds before anything reads it."""
        world = self.sim.world
        if world is None:
            raise RuntimeError("no world yet: call reset() first")
        return world

    def _observe(self) -> dict[str, np.ndarray]:
        obs, self._visible = self.sim.observe(self.target, self.num_motions, top_mask=self.naming.top_mask)
        return obs

    def _grasp_score(self, obs: dict[str, np.ndarray]) -> float:
        """The scorer's value for ``obs``, computed once per observation."""
        if self.grasp_scorer is None:
            return 0.0
        if self._score is None or self._score[0] is not obs:
            self._score = (obs, float(self.grasp_scorer(self._copy_obs({k: obs[k] for k in SIMULATOR_KEYS}))))
        return self._score[1]

    def _check_physics(self) -> dict[str, int]:
        """MuJoCo's warnings of the step (logged, and reported in info); objects thrown out
        of the room leave the scene (info's ``objects_left`` shows the loss)."""
        world = self._live_world()
        sim_warnings = world.take_warnings()
        if sim_warnings:
            gym.logger.warn(f"MuJoCo warnings during step {self.num_motions}: {sim_warnings}")
        world.remove_strays()
        return sim_warnings

    def _reset_info(self, obs: dict[str, np.ndarray]) -> dict[str, Any]:
        occluded = bool(obs["occluded"][0])
        return {
            "num_motions": 0,
            "occluded": occluded,
            "visible_fraction": self._visible,
            "objects_left": self._live_world().objects_left(),
            "target": self.target,
            "is_success": False,
            **({} if self.visuals is None else {"visual_randomization": self.visuals.to_dict(self.num_objects)}),
        }

    @staticmethod
    def _copy_obs(obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {k: v.copy() for k, v in obs.items()}
