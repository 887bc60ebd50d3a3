"""``MPGEnv``: one Gymnasium env class; each registered id is a :class:`StageSpec`.

Life of a step: decode the pixel-wise action, run the primitive in the world, observe the
new heightmaps, check occlusion and change, score the stage's reward, decide termination.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from mpg_envs.actions import PixelActionSpace
from mpg_envs.objects import ObjectAsset, load_object_set
from mpg_envs.occlusion import ChangeConfig, OcclusionConfig, change_detected, is_occluded, surrounded_sectors
from mpg_envs.primitives import PrimitiveConfig, PrimitiveResult, Primitives
from mpg_envs.rewards import RewardConfig, StepOutcome
from mpg_envs.robot import ArmIK, RobotConfig
from mpg_envs.scenes import SCENES, SceneConfig
from mpg_envs.stages import STAGES, StageSpec
from mpg_envs.workspace import Workspace
from mpg_envs.world import PhysicsConfig, World

OBS_MODES = ("raycast", "camera")
GraspScorer = Callable[[dict[str, np.ndarray]], float]


@dataclass(frozen=True)
class EnvConfig:
    """Settings shared by every stage (the paper's values by default)."""

    workspace: Workspace = Workspace()
    robot: RobotConfig = RobotConfig()
    physics: PhysicsConfig = PhysicsConfig()
    primitives: PrimitiveConfig = PrimitiveConfig()
    scene: SceneConfig = SceneConfig()
    reward: RewardConfig = RewardConfig()
    occlusion: OcclusionConfig = OcclusionConfig()
    change: ChangeConfig = ChangeConfig()
    scene_tries: int = 20  # redraws allowed to meet a stage's start condition
    raycast_threads: int | None = None  # threads per env for the heightmap; None: up to 2 (set 1 with one env per core)
    object_set_seed: int = 0


def observation_space(workspace: Workspace = Workspace()) -> spaces.Dict:
    """The observation space of every MPG env (ENV.md): colour, depth and mask heightmaps
    and the occlusion flag."""
    size = workspace.shape
    return spaces.Dict(
        {
            "color": spaces.Box(0, 255, (*size, 3), np.uint8),
            "depth": spaces.Box(0.0, workspace.z_max, size, np.float32),
            "mask": spaces.Box(0, 1, size, np.uint8),
            "occluded": spaces.MultiBinary(1),
        }
    )


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
        scene_path = options.pop("scene", None)
        mesh_dir = options.pop("mesh_dir", None)
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}; valid: ['mesh_dir', 'scene']")
        if scene_path is not None:
            from mpg_envs.scene_io import load_scene

            load_scene(self, scene_path, mesh_dir=mesh_dir)
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
        terminated = is_success or target_out or (self.stage.end_on_move_success and move_success)
        truncated = not terminated and (
            self.num_motions >= self.max_motions or (self.stage.end_after_grasp and primitive == "grasp")
        )
        info = {
            "primitive": primitive,
            "rotation": int(rotation),
            "pixel": (int(row), int(col)),
            "position": tuple(float(v) for v in result.position),
            "grasp_success": bool(result.grasp_success),
            "target_grasped": bool(target_grasped),
            "wrong_grasp": bool(primitive == "grasp" and result.grasp_success and not target_grasped),
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
        }
        return self._copy_obs(obs), reward, bool(terminated), bool(truncated), info

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
        rng = self.np_random
        stage = self.stage
        scene_fn = SCENES[stage.scene]
        for attempt in range(self.config.scene_tries):
            picks = rng.integers(len(self.object_set), size=self.num_objects)
            world = self._build_world([self.object_set[int(k)] for k in picks])
            self.target = scene_fn(world, rng, self.config.scene)
            if (stage.start_occluded is None and not stage.start_surrounded) or self.target is None:
                return
            obs = self._observe()
            occluded_ok = stage.start_occluded is None or bool(obs["occluded"][0]) == stage.start_occluded
            surrounded_ok = surrounded_sectors(obs["depth"], obs["mask"]) >= stage.start_surrounded
            if occluded_ok and surrounded_ok and not self._target_out():
                return
        # Keep the last draw: the stage's start condition could not be met in the tries given.

    def _observe(self) -> dict[str, np.ndarray]:
        from mpg_envs.footprint import footprint_mask

        world = self.world
        ws = self.config.workspace
        if self.obs_mode == "camera":
            if self._camera is None:
                from mpg_envs.camera import CameraConfig, CameraHeightmapper

                self._camera = CameraHeightmapper(world.model, self.camera_config or CameraConfig(), ws)
            hm = self._camera.heightmaps(world.data, self.np_random)
        else:
            hm = self._raycaster(world.data)
        if self.stage.mask_all_objects or self.target is None:
            ids = [world.object_geom_ids[i] for i in world.active_objects()]
        else:
            ids = [world.object_geom_ids[self.target]] if world.active[self.target] else []
        geoms = np.concatenate(ids) if ids else np.zeros(0, dtype=int)
        mask = footprint_mask(ws, world.model, world.data, geoms) if geoms.size else np.zeros(ws.shape, np.uint8)
        occluded = False
        if self.target is not None and not self.stage.mask_all_objects and world.active[self.target]:
            occluded = is_occluded(hm.depth, mask, world.object_top(self.target), self.config.occlusion)
        return {
            "color": hm.color,
            "depth": hm.depth.astype(np.float32),
            "mask": (mask > 0).astype(np.uint8),
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
