"""``MPGEnv``: one Gymnasium env class; each registered id is a :class:`StageSpec`.

Life of a step: decode the pixel-wise action, run the primitive in the world, observe the
new heightmaps, check occlusion and change, score the stage's reward, decide termination.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Sequence

import gymnasium as gym
import numpy as np

from mpg_envs.actions import PixelActionSpace
from mpg_envs.config import OBS_MODES, EnvConfig, observation_space
from mpg_envs.objects import ObjectAsset, load_object_set
from mpg_envs.occlusion import change_detected, is_occluded, surrounded_sectors
from mpg_envs.primitives import PrimitiveResult, Primitives
from mpg_envs.rewards import StepOutcome
from mpg_envs.robot import ArmIK
from mpg_envs.scene_io import (
    SceneFile,
    SceneFileError,
    SceneObject,
    kept_target,
    objects_outside,
    read_scene,
    resolve_outside,
)
from mpg_envs.scenes import SCENES, InvalidSceneError, keep_inside
from mpg_envs.stages import END_REASONS, STAGES, StageSpec, episode_end
from mpg_envs.world import World, WorldCheckpoint

__all__ = ["END_REASONS", "OBS_MODES", "RESET_OPTIONS", "EnvConfig", "MPGEnv", "observation_space"]

RESET_OPTIONS = ("scene", "mesh_dir", "drop_outside")
GraspScorer = Callable[[dict[str, np.ndarray]], float]


class MPGEnv(gym.Env):
    """Target-oriented grasping in clutter with pixel-wise move/push/grasp actions.

    Public attributes (read-only for callers; the agents package relies on them):

    Attributes:
        stage: the :class:`~mpg_envs.stages.StageSpec` this env runs (its ``name``,
            ``env_id``, ``primitives``, ``end_after_grasp``, ``mask_all_objects``, ...).
        num_objects: objects dropped at every reset (the stage's default unless given).
        primitives: the primitive names this env accepts, in action-code order.
        max_motions: the motion cap; an episode is truncated when it is reached.
        num_motions: motions taken so far in the current episode.
        target: index of the target object in the world (``None`` in Stage 1, where every
            object is a target).
        world: the :class:`~mpg_envs.world.World` of the current episode (``None`` before
            the first reset).

    Reset: a generated scene has exactly ``num_objects`` objects, all resting inside the
    workspace (objects that roll out are dropped again on the pile, deterministically from
    the seed), and meets the stage's start condition (Occluded: the target is one of the
    first five dropped and is occluded; Stage 5: the first or second dropped). When that
    cannot be made in ``config.scene_tries`` draws, reset raises
    :class:`~mpg_envs.scenes.InvalidSceneError` rather than return a lesser scene.
    ``reset(options=...)`` takes ``scene`` (a scene file, ours or a VPG test case),
    ``mesh_dir`` (meshes for a VPG case) and ``drop_outside`` (leave out, with a warning,
    the file's objects outside the workspace instead of raising
    :class:`~mpg_envs.scene_io.SceneFileError`). Reset's ``info`` has ``objects_left`` (the
    scene's object count), ``occluded``, ``target``, ``num_motions`` and ``is_success``.

    Step ``info`` has ``end_reason``: ``None`` until the episode's last step, then one of
    :data:`END_REASONS`.
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
    ):
        self.stage = STAGES[stage] if isinstance(stage, str) and stage in STAGES else stage
        if not isinstance(self.stage, StageSpec):
            raise ValueError(f"unknown stage {stage!r}; valid: {sorted(STAGES)}")
        stage_spec = self.stage
        self.num_objects = stage_spec.num_objects if num_objects is None else num_objects
        if not isinstance(self.num_objects, (int, np.integer)) or not stage_spec.min_objects <= self.num_objects <= 60:
            raise ValueError(f"num_objects must be an integer in {stage_spec.min_objects}..60 for {stage_spec.name}, got {num_objects!r}")
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
        self.num_motions = 0

    # ------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - set(RESET_OPTIONS))
        if unknown:
            raise ValueError(f"unknown reset options {unknown}; valid: {sorted(RESET_OPTIONS)}")
        if options.get("scene") is not None:
            scene = read_scene(options["scene"], options.get("mesh_dir"), self.config.object_set_seed)
            self._apply_scene(scene, drop_outside=bool(options.get("drop_outside", False)))
        else:
            self._generate_scene()
        self.num_motions = 0
        self._obs = self._observe()
        self._score = None
        return self._copy_obs(self._obs), self._reset_info()

    def step(self, action):
        if self.world is None or self._obs is None:
            raise RuntimeError("call reset() before step()")
        primitive, rotation, row, col = self.action_space.decode(action)
        before = self._obs
        occluded_before = bool(before["occluded"][0])
        score_before = self._grasp_score(before) if primitive != "grasp" else None
        result = self._primitives.execute(primitive, rotation, row, col, before["depth"], self.target)
        self.num_motions += 1
        sim_warnings = self._check_physics()
        obs = self._observe()
        self._obs = obs
        target_grasped = self._target_grasped(result)
        target_out = self.target is not None and self._target_out()
        occluded = bool(obs["occluded"][0])
        changed = change_detected(before["depth"], obs["depth"], before["mask"], result.grasp_success, self.config.change)
        move_success = primitive == "move" and occluded_before and not occluded and not target_grasped and not target_out
        gain = 0.0
        if score_before is not None:
            gain = self._grasp_score(obs) - score_before
        outcome = StepOutcome(primitive, result.grasp_success, target_grasped, move_success, changed, gain)
        reward = float(self.stage.reward(outcome, self.config.reward))
        objects_left = self._objects_left()
        is_success = objects_left == 0 if self.stage.mask_all_objects else bool(target_grasped and primitive == "grasp")
        terminated, truncated, end_reason = episode_end(
            self.stage,
            is_success=is_success,
            target_out=target_out,
            move_success=move_success,
            primitive=primitive,
            num_motions=self.num_motions,
            max_motions=self.max_motions,
        )
        info = {
            "primitive": primitive,
            "rotation": int(rotation),
            "pixel": (int(row), int(col)),
            "position": tuple(float(v) for v in result.position),
            "grasp_success": bool(result.grasp_success),
            "target_grasped": bool(target_grasped),
            "wrong_grasp": bool(primitive == "grasp" and result.grasp_success and not target_grasped),
            "grasp_failure": result.grasp_failure,  # why a grasp or move held nothing (GRASP_FAILURES), else None
            "unreachable": bool(result.unreachable),  # the arm could not reach the pose: nothing moved
            "change_detected": bool(changed),
            "occluded_before": occluded_before,
            "occluded": occluded,
            "move_success": bool(move_success),
            "num_motions": self.num_motions,
            "is_success": bool(is_success),
            "objects_left": objects_left,
            "target_out_of_workspace": bool(target_out),
            "grasp_q_gain": float(gain),
            "physics_steps": int(result.physics_steps),
            "sim_warnings": sim_warnings,
            "end_reason": end_reason,
        }
        return self._copy_obs(obs), reward, bool(terminated), bool(truncated), info

    def try_step(self, action):
        """What ``step(action)`` returns, with the episode then put back exactly as it was.

        A counterfactual that only a simulator can give (the world, the motion count, the
        last observation and the noise generator are restored; MuJoCo is deterministic, so
        ``step(action)`` afterwards returns the same). Trainers may use it to label actions
        they did not take; a policy under evaluation must not.
        """
        if self.world is None or self._obs is None:
            raise RuntimeError("call reset() before try_step()")
        checkpoint = WorldCheckpoint(self.world)
        saved = (self.num_motions, self._obs, self._score, self.np_random.bit_generator.state)
        try:
            return self.step(action)
        finally:
            checkpoint.restore()
            self.num_motions, self._obs, self._score, self.np_random.bit_generator.state = saved

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self.world is None:
            raise RuntimeError("call reset() before render()")
        from mpg_envs.render import render_overview

        if self._renderer is None or self._renderer.model is not self.world.model:
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = render_overview(self.world.model)
        return self._renderer.render(self.world.data)

    def close(self):
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
            from mpg_envs.camera import CameraConfig, add_cameras

            cam_cfg = self.camera_config or CameraConfig()
            hook = lambda spec: add_cameras(spec, cam_cfg)  # noqa: E731
        world = World(assets, self.config.workspace, self.config.robot, self.config.physics, extra_spec_hook=hook)
        self.world = world
        self._primitives = Primitives(world, self.config.primitives, self._ik)
        # Heightmappers are bound to one compiled model.
        for name in ("_raycaster", "_camera"):
            old = getattr(self, name)
            if old is not None:
                old.close()
            setattr(self, name, None)
        if self.obs_mode == "raycast":
            from mpg_envs.heightmap import RaycastHeightmapper

            self._raycaster = RaycastHeightmapper(world.model, self.config.workspace, num_threads=self.config.raycast_threads)
        return world

    def _generate_scene(self) -> None:
        """Draw scenes until one is valid (see the class docstring); sets world and target."""
        rng = self.np_random
        stage = self.stage
        scene_fn = SCENES[stage.scene]
        astray_draws = 0
        for _ in range(self.config.scene_tries):
            picks = rng.integers(len(self.object_set), size=self.num_objects)
            world = self._build_world([self.object_set[int(k)] for k in picks])
            layout = scene_fn(world, rng, self.config.scene)
            redropped = keep_inside(world, rng, layout, self.config.scene)
            if redropped is None:
                astray_draws += 1
                continue
            if not layout.targets:
                self.target = None
                return
            # Re-dropped objects landed on the pile afterwards: no longer "the n-th dropped".
            target = self._first_acceptable_target([t for t in layout.targets if t not in redropped])
            if target is not None:
                self.target = target
                return
        raise InvalidSceneError(
            f"{stage.env_id}: no valid scene of {self.num_objects} objects in {self.config.scene_tries} draws "
            f"({astray_draws} with objects left outside the workspace or not at rest after "
            f"{self.config.scene.redrop_rounds} re-drop rounds, the others with no candidate target meeting the "
            f"start condition: occluded={stage.start_occluded}, surrounded sectors>={stage.start_surrounded}). "
            f"Raise EnvConfig.scene_tries or use fewer objects."
        )

    def _first_acceptable_target(self, candidates: Sequence[int]) -> int | None:
        """The first candidate meeting the stage's start condition (occlusion, surround)."""
        stage = self.stage
        if stage.start_occluded is None and not stage.start_surrounded:
            return candidates[0] if candidates else None
        depth = self._heightmaps().depth
        for target in candidates:
            mask, occluded = self._target_view(depth, target)
            if stage.start_occluded is not None and occluded != stage.start_occluded:
                continue
            if surrounded_sectors(depth, mask) >= stage.start_surrounded:
                return target
        return None

    def _apply_scene(self, scene: SceneFile, drop_outside: bool) -> None:
        """Build the world of a scene file; objects outside the workspace raise
        :class:`SceneFileError` or, with ``drop_outside``, are left out with a warning."""
        ws = self.config.workspace
        dropped = objects_outside(scene, ws)
        resolve_outside(scene, dropped, ws, drop_outside, "in the file")
        world = self._build_world([obj.asset for obj in scene.objects])
        for i, obj in enumerate(scene.objects):
            if obj.active and i not in dropped:
                world.set_object_pose(i, obj.position, obj.quat)
        world.forward()
        if scene.settle:
            world.settle(4 * world.physics.settle_max_steps)
            moved_out = sorted(set(world.objects_out_of_room().tolist()) | set(world.objects_outside_workspace().tolist()))
            positions = np.array([world.object_position(i) for i in moved_out]).reshape(-1, 3)
            resolve_outside(scene, moved_out, ws, drop_outside, "after settling", positions)
            for i in moved_out:
                world.remove_object(i)
            world.forward()
            dropped = dropped + moved_out
        self.target = kept_target(scene, set(dropped))
        if self.target is None and not self.stage.mask_all_objects:
            raise SceneFileError(f"scene {scene.source!r} has no target; {self.stage.env_id} needs one")

    def current_scene(self) -> SceneFile:
        """The current scene (every object's asset, pose and state, the target), as
        :func:`mpg_envs.scene_io.save_scene` writes it."""
        world = self.world
        if world is None:
            raise RuntimeError("call reset() before current_scene()")
        objects = tuple(
            SceneObject(asset, *world.object_pose(i), active=bool(world.active[i]), label=f"object {i} ({asset.name!r})")
            for i, asset in enumerate(world.assets)
        )
        return SceneFile(objects, self.target, "", self.stage.name, self.config.object_set_seed)

    def _heightmaps(self):
        """Colour and depth heightmaps of the current state (ray-cast or camera)."""
        if self.obs_mode == "camera":
            if self._camera is None:
                from mpg_envs.camera import CameraConfig, CameraHeightmapper

                self._camera = CameraHeightmapper(self.world.model, self.camera_config or CameraConfig(), self.config.workspace)
            return self._camera.heightmaps(self.world.data, self.np_random)
        return self._raycaster(self.world.data)

    def _target_view(self, depth: np.ndarray, target: int | None) -> tuple[np.ndarray, bool]:
        """The mask heightmap for ``target`` (every object in Stage 1) and whether it is occluded."""
        from mpg_envs.footprint import footprint_mask

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

    def _observe(self) -> dict[str, np.ndarray]:
        hm = self._heightmaps()
        mask, occluded = self._target_view(hm.depth, self.target)
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

    def _target_grasped(self, result: PrimitiveResult) -> bool:
        if self.stage.mask_all_objects:
            return bool(result.grasp_success)
        return bool(result.grasp_success and result.grasped_object == self.target)

    def _target_out(self) -> bool:
        world = self.world
        if self.target is None or not world.active[self.target]:
            return False
        return self.target in set(world.objects_outside_workspace().tolist())

    def _check_physics(self) -> dict[str, int]:
        """Deal with what the physics may have done wrong; returns MuJoCo's warning counts."""
        sim_warnings = self.world.warnings_raised()
        if sim_warnings:
            # Reported in info and cleared, so each step's count is its own.
            gym.logger.warn(f"MuJoCo warnings during step {self.num_motions}: {sim_warnings}")
            for w in self.world.data.warning:
                w.number = 0
        bad = self.world.objects_out_of_room()
        if len(bad):
            # An unstable contact threw something out of the room: take it out of the scene so
            # it can't poison later steps; the info's objects_left reflects the loss.
            for i in bad:
                self.world.remove_object(int(i))
            self.world.forward()
        return sim_warnings

    def _objects_left(self) -> int:
        """Objects still in the scene and inside the workspace."""
        return int(self.world.active.sum() - len(self.world.objects_outside_workspace()))

    def _reset_info(self) -> dict[str, Any]:
        occluded = bool(self._obs["occluded"][0])
        return {
            "num_motions": 0,
            "occluded": occluded,
            "objects_left": self._objects_left(),
            "target": self.target,
            "is_success": False,
        }

    @staticmethod
    def _copy_obs(obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {k: v.copy() for k, v in obs.items()}
