"""``MPGEnv``: one Gymnasium env class; each registered id is a :class:`StageSpec`.

Life of a step, as named hooks: decode the pixel-wise action, run the primitive in the world,
observe (heightmaps, target mask, occlusion, visible fraction), ``evaluate`` what the step did
(a :class:`~mpg_envs.tasks.step_evaluation.StepEvaluation`), ``step_reward`` it, and decide the end
(:func:`~mpg_envs.tasks.stages.episode_end`). A reset's scene comes from ``_load_scene``: a scene
file, the shipped test set of the seed, or a fresh drop (:mod:`mpg_envs.tasks.scene_source`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Sequence

import gymnasium as gym
import numpy as np

from mpg_envs.grid.actions import PixelActionSpace
from mpg_envs.tasks.config import OBS_MODES, EnvConfig, observation_space
from mpg_envs.simulation.objects import ObjectAsset, load_object_set
from mpg_envs.perception.occlusion import change_detected, check_band, is_occluded, visible_fraction
from mpg_envs.perception.visual_randomization import VisualRandomization, episode_visuals, randomized_raycast
from mpg_envs.simulation.primitives import PrimitiveResult, Primitives
from mpg_envs.tasks.rewards import StepOutcome
from mpg_envs.tasks.scene_source import draw_scene, shipped_scene
from mpg_envs.tasks.step_evaluation import StepEvaluation, action_info
from mpg_envs.simulation.robot import ArmIK
from mpg_envs.scenes.scene_io import SceneFile, SceneFileError, read_scene
from mpg_envs.scenes.scene_loading import apply_scene, scene_of
from mpg_envs.scenes.generators import InvalidSceneError
from mpg_envs.tasks.stages import END_REASONS, STAGES, WRONG_GRASP_RULES, StageSpec, episode_end
from mpg_envs.simulation.world import World, WorldCheckpoint

__all__ = ["END_REASONS", "OBS_MODES", "RESET_OPTIONS", "EnvConfig", "InvalidSceneError", "MPGEnv", "StepEvaluation", "observation_space"]

RESET_OPTIONS = ("scene", "mesh_dir", "drop_outside", "num_objects")
GraspScorer = Callable[[dict[str, np.ndarray]], float]


class MPGEnv(gym.Env):
    """Target-oriented grasping in clutter with pixel-wise move/push/grasp actions.

    Attributes (read-only for callers; the agents package relies on them):
        stage: the :class:`~mpg_envs.tasks.stages.StageSpec` this env runs (its ``name``,
            ``env_id``, ``primitives``, ``end_after_grasp``, ``mask_all_objects``, ...).
        num_objects: objects dropped at every reset (the stage's default unless given).
        primitives: the primitive names this env accepts, in action-code order.
        max_motions: the motion cap; an episode is truncated when it is reached.
        num_motions: motions taken so far in the current episode.
        target: index of the target object in the world (``None`` in Stage 1: every object is a target).
        world: the :class:`~mpg_envs.simulation.world.World` of the current episode (``None`` before the first reset).

    Keywords beyond the stage: ``wrong_grasp`` (``"remove"``, the paper's protocol, or ``"fail"``: strict
    retrieval, a mis-pick ends the episode), ``visible_range`` (a band of the target's visible fraction at
    reset), ``use_test_set`` (True or False: load the shipped scenes of the test seeds, or generate every scene).

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
    the episode ended, before the first ``reset()`` or after ``close()`` raises ``RuntimeError``
    until the next ``reset()``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 2}

    def __init__(
        self,
        stage: str | StageSpec = "Stage5",
        num_objects: int | None = None,
        obs_mode: str = "raycast",
        object_set: str | Sequence[ObjectAsset] = "blocks",
        max_motions: int | None = None,
        grasp_scorer: GraspScorer | None = None,
        render_mode: str | None = None,
        config: EnvConfig = EnvConfig(),
        camera_config: Any = None,
        wrong_grasp: str | None = None,
        visible_range: tuple[float, float] | None = None,
        use_test_set: bool = True,
        visual_randomization: Any = None,
    ):
        self.stage = STAGES[stage] if isinstance(stage, str) and stage in STAGES else stage
        if not isinstance(self.stage, StageSpec):
            raise ValueError(f"unknown stage {stage!r}; valid: {sorted(STAGES)}")
        stage_spec = self.stage
        self.num_objects = self._checked_num_objects(stage_spec.num_objects if num_objects is None else num_objects)
        self.default_num_objects = self.num_objects
        self.wrong_grasp = stage_spec.wrong_grasp if wrong_grasp is None else wrong_grasp
        if self.wrong_grasp not in WRONG_GRASP_RULES:
            raise ValueError(f"wrong_grasp must be one of {WRONG_GRASP_RULES}, got {wrong_grasp!r}")
        if self.wrong_grasp == "fail" and stage_spec.mask_all_objects:
            raise ValueError(f"wrong_grasp='fail' needs a target; {stage_spec.env_id} has none (every object is a target)")
        self.visible_range = check_band(stage_spec.visible_range if visible_range is None else visible_range)
        if self.visible_range is not None and stage_spec.mask_all_objects:
            raise ValueError(f"visible_range needs a target; {stage_spec.env_id} has none (every object is a target)")
        if not isinstance(use_test_set, (bool, np.bool_)):
            raise ValueError(f"use_test_set must be True or False, got {use_test_set!r}")
        self.use_test_set = bool(use_test_set)
        self.max_motions = stage_spec.max_motions if max_motions is None else max_motions
        if not isinstance(self.max_motions, (int, np.integer)) or self.max_motions < 1:
            raise ValueError(f"max_motions must be a positive integer, got {max_motions!r}")
        if obs_mode not in OBS_MODES:
            raise ValueError(f"obs_mode must be one of {OBS_MODES}, got {obs_mode!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        if grasp_scorer is not None and not callable(grasp_scorer):
            raise ValueError("grasp_scorer must be a callable obs -> float")
        self.config = config
        self.obs_mode = obs_mode
        self.render_mode = render_mode
        self.grasp_scorer = grasp_scorer
        self.camera_config = camera_config
        self.visual_randomization = VisualRandomization.from_option(visual_randomization)  # None: off
        self.visuals = None  # this episode's drawn EpisodeVisuals
        self.object_set = (
            load_object_set(object_set, seed=config.object_set_seed) if isinstance(object_set, (str, Path)) else list(object_set)
        )
        if not self.object_set:
            raise ValueError("object_set is empty")
        self._object_set_name = str(object_set) if isinstance(object_set, (str, Path)) else "custom"
        self.primitives = stage_spec.primitives
        size = config.workspace.shape
        self.action_space = PixelActionSpace(self.primitives, size=size[0])
        self.observation_space = observation_space(config.workspace)
        self._ik = ArmIK(config.robot)
        self._raycaster = None
        self._camera = None
        self._renderer = None
        self.world: World | None = None
        self.target: int | None = None
        self._obs: dict[str, np.ndarray] | None = None
        self._score: tuple[dict, float] | None = None  # (observation, its grasp score)
        self._visible: float | None = None  # the target's visible fraction in the last observation
        self.num_motions = 0
        self._ended: str | None = "call reset() before step()"  # why step() may not run now (None: it may)

    # ------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - set(RESET_OPTIONS))
        if unknown:
            raise ValueError(f"unknown reset options {unknown}; valid: {sorted(RESET_OPTIONS)}")
        self.num_objects = self._checked_num_objects(options.get("num_objects", self.default_num_objects))
        self.visuals = None  # a drawn scene's start condition is judged unrandomized: the same scenes either way
        self._load_scene(seed, options)
        self.num_motions, self._ended = 0, None
        self.visuals = episode_visuals(self.visual_randomization, seed, self.np_random)
        self._obs = self._observe()
        self._score = None
        return self._copy_obs(self._obs), self._reset_info()

    def step(self, action):
        if self._ended is not None:
            raise RuntimeError(self._ended)
        primitive, rotation, row, col = self.action_space.decode(action)
        before = self._obs
        score_before = self._grasp_score(before) if primitive != "grasp" else None
        visible_before = self._visible
        result = self._primitives.execute(primitive, rotation, row, col, before["depth"], self.target)
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
        self._ended = None if end_reason is None else f"the episode has ended ({end_reason}); call reset() before step()"
        return self._copy_obs(self._obs), reward, bool(terminated), bool(truncated), info

    # ------------------------------------------------------------ task hooks
    def _load_scene(self, seed: int | None, options: dict[str, Any]) -> None:
        """Build this episode's world and target: a scene file, else the shipped test set's
        scene of ``seed``, else objects dropped afresh (:mod:`mpg_envs.tasks.scene_source`)."""
        scene = options.get("scene")
        if scene is not None:
            if not isinstance(scene, SceneFile):
                scene = read_scene(scene, options.get("mesh_dir"), self.config.object_set_seed)
            self._apply_scene(scene, drop_outside=bool(options.get("drop_outside", False)))
            return
        fixed = shipped_scene(self, seed)
        if fixed is not None:
            self._apply_scene(fixed, drop_outside=False)
        else:
            draw_scene(self)

    def evaluate(
        self, primitive: str, before: dict[str, np.ndarray], result: PrimitiveResult, score_before: float | None, visible_before: float | None = None
    ) -> StepEvaluation:
        """What the step did, judged on the new state (success, mis-pick, move success,
        occlusion, visibility and its gain over ``visible_before``, change); the reward and
        the episode's end are read off it."""
        obs, world, target = self._obs, self.world, self.target
        target_grasped = bool(result.grasp_success and (self.stage.mask_all_objects or result.grasped_object == target))
        target_out = target is not None and bool(world.active[target]) and target in set(world.objects_outside_workspace().tolist())
        occluded_before = bool(before["occluded"][0])
        occluded = bool(obs["occluded"][0])
        changed = change_detected(before["depth"], obs["depth"], before["mask"], result.grasp_success, self.config.change)
        cleared = occluded_before and not occluded and not target_grasped and not target_out
        move_success = primitive == "move" and cleared
        gain = 0.0 if score_before is None else self._grasp_score(obs) - score_before
        wrong = bool(primitive == "grasp" and result.grasp_success and not target_grasped)
        is_success = self.world.objects_left() == 0 if self.stage.mask_all_objects else bool(target_grasped and primitive == "grasp")
        seen = 0.0 if self._visible is None or visible_before is None else self._visible - visible_before
        return StepEvaluation(
            outcome=StepOutcome(primitive, result.grasp_success, target_grasped, move_success, changed, gain, seen,
                                covered_before=occluded_before, cleared=cleared),
            wrong_grasp=wrong,
            ends_wrong_object=wrong and self.wrong_grasp == "fail",
            is_success=is_success,
            target_out=bool(target_out),
            occluded_before=occluded_before,
            occluded=occluded,
            visible_fraction=self._visible,
            objects_left=self.world.objects_left(),
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
        checkpoint = WorldCheckpoint(self.world)
        saved = (self.num_motions, self._obs, self._score, self._visible, self.np_random.bit_generator.state, self._ended)
        try:
            return self.step(action)
        finally:
            checkpoint.restore()
            self.num_motions, self._obs, self._score, self._visible, self.np_random.bit_generator.state, self._ended = saved

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self.world is None:
            raise RuntimeError("call reset() before render()")
        from mpg_envs.perception.render import render_overview

        if self._renderer is None or self._renderer.model is not self.world.model:
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = render_overview(self.world.model)
        return self._renderer.render(self.world.data)

    def close(self):
        self._ended = "the env is closed; call reset() to start a new episode before step()"
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        for name in ("_raycaster", "_camera"):
            if getattr(self, name) is not None:
                getattr(self, name).close()
                setattr(self, name, None)

    # ------------------------------------------------------------ helpers
    @property
    def target_index(self) -> int | None:
        """Index of the target object in ``world`` (``None`` in Stage I)."""
        return self.target

    def _build_world(self, assets: Sequence[ObjectAsset]) -> World:
        hook = None
        if self.obs_mode == "camera":
            from mpg_envs.perception.camera import CameraConfig, add_cameras

            cam_cfg = self.camera_config or CameraConfig()
            hook = lambda spec: add_cameras(spec, cam_cfg)  # noqa: E731
        # The arm's visual meshes matter only to pictures: leave them out unless something renders.
        visual = self.render_mode is not None or self.obs_mode == "camera"
        world = World(assets, self.config.workspace, self.config.robot, self.config.physics, extra_spec_hook=hook, robot_visual=visual)
        self.world = world
        self._primitives = Primitives(world, self.config.primitives, self._ik)
        # Heightmappers are bound to one compiled model.
        threads = self.config.raycast_threads or (self._raycaster.num_threads if self._raycaster else None)
        for name in ("_raycaster", "_camera"):
            if getattr(self, name) is not None:
                getattr(self, name).close()
            setattr(self, name, None)
        if self.obs_mode == "raycast":
            from mpg_envs.perception.heightmap import RaycastHeightmapper

            # The thread count is chosen once per env (choosing samples the machine's load).
            self._raycaster = RaycastHeightmapper(world.model, self.config.workspace, num_threads=threads)
        return world

    def _apply_scene(self, scene: SceneFile, drop_outside: bool) -> None:
        """Build the world of a scene file (:func:`mpg_envs.scenes.scene_loading.apply_scene`)."""
        _, self.target = apply_scene(self._build_world, scene, self.config.workspace, drop_outside)
        if self.target is None and not self.stage.mask_all_objects:
            raise SceneFileError(f"scene {scene.source!r} has no target; {self.stage.env_id} needs one")

    def current_scene(self) -> SceneFile:
        """The current scene (every object's asset, pose and state, the target), as
        :func:`mpg_envs.scenes.scene_io.save_scene` writes it."""
        if self.world is None:
            raise RuntimeError("call reset() before current_scene()")
        return scene_of(self.world, self.target, self.stage.name, self.config.object_set_seed)

    def _heightmaps(self):
        """Colour and depth heightmaps of the current state (ray-cast or camera)."""
        rng = self.np_random if self.visuals is None else self.visuals.noise_rng(self.num_motions)  # depth noise
        if self.obs_mode == "camera":
            if self._camera is None:
                from mpg_envs.perception.camera import CameraConfig, CameraHeightmapper

                self._camera = CameraHeightmapper(self.world.model, self.camera_config or CameraConfig(), self.config.workspace)
            return self._camera.heightmaps(self.world.data, rng, self.visuals)
        if self.visuals is not None:
            return randomized_raycast(self._raycaster, self.world.data, self.visuals, rng)
        return self._raycaster(self.world.data)

    def _target_view(self, depth: np.ndarray, target: int | None) -> tuple[np.ndarray, bool]:
        """The mask heightmap for ``target`` (every object in Stage 1) and whether it is occluded."""
        from mpg_envs.perception.footprint import footprint_mask

        world = self.world
        ws = self.config.workspace
        if self.stage.mask_all_objects or target is None:
            ids = [world.object_geom_ids[i] for i in world.active_objects()]
        else:
            ids = [world.object_geom_ids[target]] if world.active[target] else []
        geoms = np.concatenate(ids) if ids else np.zeros(0, dtype=int)
        mask = footprint_mask(ws, world.model, world.data, geoms) if geoms.size else np.zeros(ws.shape, np.uint8)
        occluded = False
        if target is not None and not self.stage.mask_all_objects and world.active[target]:
            occluded = is_occluded(depth, mask, world.object_top(target), self.config.occlusion)
        return (mask > 0).astype(np.uint8), bool(occluded)

    def _visible_fraction(self, maps, mask: np.ndarray, target: int | None) -> float | None:
        """Share of ``target``'s footprint ``mask`` where the target is the top surface, from
        the geom seen at each pixel (ray casts, or the camera mode's segmentation render)."""
        if target is None or self.stage.mask_all_objects or not self.world.active[target] or maps.geom_id is None:
            return None
        return visible_fraction(mask, maps.geom_id, self.world.object_geom_ids[target])

    def _observe(self) -> dict[str, np.ndarray]:
        hm = self._heightmaps()
        mask, occluded = self._target_view(hm.depth, self.target)
        self._visible = self._visible_fraction(hm, mask, self.target)
        return {
            "color": hm.color,
            "depth": hm.depth.astype(np.float32),
            "mask": mask,
            "occluded": np.array([int(occluded)], dtype=np.int8),
        }

    def _grasp_score(self, obs: dict[str, np.ndarray]) -> float:
        """The scorer's value for ``obs``, computed once per observation."""
        if self.grasp_scorer is None:
            return 0.0
        if self._score is None or self._score[0] is not obs:
            self._score = (obs, float(self.grasp_scorer(self._copy_obs(obs))))
        return self._score[1]

    def _check_physics(self) -> dict[str, int]:
        """MuJoCo's warnings of the step (logged, and reported in info); objects thrown out
        of the room leave the scene (info's ``objects_left`` shows the loss)."""
        sim_warnings = self.world.take_warnings()
        if sim_warnings:
            gym.logger.warn(f"MuJoCo warnings during step {self.num_motions}: {sim_warnings}")
        self.world.remove_strays()
        return sim_warnings

    def _checked_num_objects(self, n: Any) -> int:
        stage = self.stage
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not stage.min_objects <= n <= 60:
            raise ValueError(f"num_objects must be an integer in {stage.min_objects}..60 for {stage.env_id}, got {n!r}")
        return int(n)

    def _reset_info(self) -> dict[str, Any]:
        occluded = bool(self._obs["occluded"][0])
        return {
            "num_motions": 0,
            "occluded": occluded,
            "visible_fraction": self._visible,
            "objects_left": self.world.objects_left(),
            "target": self.target,
            "is_success": False,
            **({} if self.visuals is None else {"visual_randomization": self.visuals.to_dict(self.num_objects)}),
        }

    @staticmethod
    def _copy_obs(obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {k: v.copy() for k, v in obs.items()}
