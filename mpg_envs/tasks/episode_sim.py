"""The simulation of an episode, one public handle (as dm_control composer's ``physics``).

:class:`EpisodeSim` holds what an episode runs on: the world, the primitives executor that
moves in it, the views of it (ray-cast or camera heightmaps; the target's mask, occlusion
flag and visible fraction), the random generator of the episode, and try-and-undo (a
checkpoint of the world and the generator). :class:`~mpg_envs.tasks.env.MPGEnv` owns one
(``env.sim``) and hands it to whatever makes or reads its scenes: scene making
(:mod:`mpg_envs.tasks.scene_source`), the scripted oracle, diagnostics and benchmarks.

A world is compiled for one list of objects: :meth:`EpisodeSim.build` compiles a new one
only when the list changes, and otherwise puts the one it has back in its freshly built state
(:meth:`~mpg_envs.simulation.world.World.reset`: the same state, bit for bit), keeping the
executor and the ray-caster bound to it (ray-cast mode; the camera mode compiles afresh).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np

from mpg_envs.perception.camera import CameraConfig, CameraHeightmapper, add_cameras
from mpg_envs.perception.footprint import footprint_mask
from mpg_envs.perception.heightmap import RaycastHeightmapper, geom_colors
from mpg_envs.perception.occlusion import is_occluded, visible_fraction
from mpg_envs.perception.visual_randomization import EpisodeVisuals, randomized_raycast
from mpg_envs.simulation.assets import ObjectAsset
from mpg_envs.simulation.primitives import PrimitiveExecutor, PrimitiveResult
from mpg_envs.simulation.robot import ArmIK
from mpg_envs.simulation.world import World, WorldCheckpoint
from mpg_envs.tasks.config import OBS_MODES, EnvConfig

__all__ = ["EpisodeSim", "SimCheckpoint"]


class SimCheckpoint:
    """The world and the random generator of an :class:`EpisodeSim` at one moment, to return to."""

    def __init__(self, sim: EpisodeSim):
        self.sim = sim
        if sim.world is None:
            raise RuntimeError("no world yet: reset the env (or build a world) first")
        self.world = WorldCheckpoint(sim.world)
        self.random_state = None if sim.random is None else sim.random.bit_generator.state

    def restore(self) -> None:
        """Put the world and the generator back as they were (MuJoCo is deterministic, so
        what runs next runs as it would have then)."""
        self.world.restore()
        if self.random_state is not None and self.sim.random is not None:  # (both or neither)
            self.sim.random.bit_generator.state = self.random_state


class EpisodeSim:
    """The world of an episode, what moves in it, what sees it, and how to undo.

    Attributes:
        config: the env's settings (workspace, robot, physics, primitives, occlusion, ...).
        obs_mode: ``"raycast"`` or ``"camera"`` (:data:`~mpg_envs.tasks.config.OBS_MODES`).
        mask_all_objects: the mask shows every object (Stage I), not one target.
        world: the current :class:`~mpg_envs.simulation.world.World` (``None`` before the first build).
        executor: the :class:`~mpg_envs.simulation.primitives.PrimitiveExecutor` that runs
            move/push/grasp on ``world``.
        random: the episode's generator (the env's ``np_random``; camera noise and scene
            drops draw from it), set by :meth:`initialize_episode`.
        ik: the arm's inverse kinematics (one per env; no state of a world: another
            simulation's may be handed in, ``ik=``, since making one takes a while).
        visuals: the episode's drawn visual randomization
            (:class:`~mpg_envs.perception.visual_randomization.EpisodeVisuals`), set by the env
            after the scene is made (``None``: off, and while a scene is drawn).
    """

    def __init__(
        self,
        config: EnvConfig = EnvConfig(),
        *,
        obs_mode: str = "raycast",
        camera_config: Any = None,
        robot_visual: bool = False,
        mask_all_objects: bool = False,
        ik: ArmIK | None = None,
    ):
        if obs_mode not in OBS_MODES:
            raise ValueError(f"obs_mode must be one of {OBS_MODES}, got {obs_mode!r}")
        self.config = config
        self.obs_mode = obs_mode
        self.camera_config = camera_config
        self.robot_visual = bool(robot_visual)
        self.mask_all_objects = bool(mask_all_objects)
        self.ik = ArmIK(config.robot) if ik is None else ik
        self.world: World | None = None
        self.executor: PrimitiveExecutor | None = None
        self.random: np.random.Generator | None = None
        self.visuals: EpisodeVisuals | None = None
        self._assets: tuple[ObjectAsset, ...] | None = None
        self._raycaster: RaycastHeightmapper | None = None  # ray-cast mode (made by build)
        self._occlusion_caster: RaycastHeightmapper | None = (
            None  # camera mode: the clean view the occlusion flag is judged on
        )
        self._camera: CameraHeightmapper | None = None
        self._raycast_threads = config.raycast_threads
        self._painted = False  # paint_objects was called: the ray casts read the model's colours live

    # ------------------------------------------------------------ the world
    def initialize_episode(self, random_state: np.random.Generator) -> None:
        """Start an episode drawing from ``random_state`` (the env's ``np_random``)."""
        self.random = random_state

    def build(self, assets: Sequence[ObjectAsset]) -> World:
        """A world holding ``assets`` (in this order), every object parked, the arm at home.

        The same list as the current world's reuses it, reset (with its executor and
        ray-caster; ray-cast mode); any other list compiles a new world."""
        assets = tuple(assets)
        # Camera mode renders the model (and may change its look): it keeps a fresh world each time.
        reuse = self.obs_mode == "raycast" and self._assets is not None and _same_assets(assets, self._assets)
        if reuse and self.world is not None:
            self.world.reset()
            if self.executor is not None and self.executor.memo is not None:
                self.executor.memo.clear()  # states of the last episode's world
            return self.world
        hook = None
        if self.obs_mode == "camera":
            cam_cfg = self.camera_config or CameraConfig()
            hook = lambda spec: add_cameras(spec, cam_cfg)  # noqa: E731
        c = self.config
        world = World(assets, c.workspace, c.robot, c.physics, extra_spec_hook=hook, robot_visual=self.robot_visual)
        self.world, self._assets = world, assets
        self.executor = PrimitiveExecutor(world, c.primitives, self.ik)
        self._close_views()  # heightmappers are bound to one compiled model
        if self.obs_mode == "raycast":
            # The thread count is chosen once per env (choosing samples the machine's load).
            self._raycaster = RaycastHeightmapper(world.model, c.workspace, num_threads=self._raycast_threads)
            self._raycast_threads = self._raycaster.num_threads
        return world

    def close(self) -> None:
        """Free the heightmappers' threads and renderers (the next :meth:`build` compiles afresh)."""
        self._close_views()
        self._assets = None

    def _close_views(self) -> None:
        for view in (self._raycaster, self._camera, self._occlusion_caster):
            if view is not None:
                view.close()
        self._raycaster = self._camera = self._occlusion_caster = None

    # ------------------------------------------------------------ views
    def heightmaps(self, motion: int = 0):
        """Colour and depth heightmaps of the current state, with the geom seen at each
        pixel (:class:`~mpg_envs.perception.heightmap.Heightmaps`; ray-cast or camera).

        With ``visuals`` drawn, the depth noise comes from the episode's seed and ``motion``
        (the motion count), so a trial sees the noise the real step then sees."""
        world = self._built()
        rng = self.random if self.visuals is None else self.visuals.noise_rng(motion)
        if self.obs_mode == "camera":
            if self._camera is None:
                self._camera = CameraHeightmapper(world.model, self.camera_config or CameraConfig(), self.config.workspace)
            return self._camera.heightmaps(world.data, rng, self.visuals)
        caster = self._ray_caster()
        if self.visuals is not None:
            assert rng is not None  # the visuals' own noise stream
            return randomized_raycast(caster, world.data, self.visuals, rng, camera_centres=self._camera_centres())
        if self._painted:
            return caster(world.data, geom_colors(world.model))
        return caster(world.data)

    def paint_objects(self, rgba: Sequence[Sequence[float]]) -> None:
        """Give object ``i`` of the current world the colour ``rgba[i]`` (RGBA in [0, 1]) in every
        view from now on: colours only, the physics is unchanged. It stays on the world until
        painted again (a reused world keeps the last colours).

        Raises:
            ValueError: not one colour of four values in [0, 1] per object.
        """
        world = self._built()
        colours = np.asarray(rgba, dtype=float)
        if colours.shape != (world.num_objects, 4) or not np.all((colours >= 0.0) & (colours <= 1.0)):
            raise ValueError(
                f"paint_objects needs one RGBA colour in [0, 1] per object ({world.num_objects}, 4), got shape {colours.shape}"
            )
        for geoms, colour in zip(world.object_geom_ids, colours):
            world.model.geom_rgba[geoms] = colour
        self._painted = True

    def _camera_centres(self) -> np.ndarray | None:
        """The camera mode's calibrated camera centres, where the ray-cast path places its
        heightmaps as those cameras would (``raycast_misregistration``); else ``None``."""
        if self.visuals is None or not self.visuals.raycast_misregistration:
            return None
        return np.array([cam.position for cam in (self.camera_config or CameraConfig()).cameras], dtype=float)

    def _occlusion_depth(self, maps) -> np.ndarray:
        """The depth the occlusion flag is judged on: the observation's own in ray-cast mode; in
        camera mode a clean top-down ray cast of the same state. The flag compares the depth
        inside the target's true footprint with its true top; a camera's heightmap is placed by
        its calibrated pose, up to about 1 cm off the true one, and with depth noise a
        neighbour's rim inside the footprint flagged clear targets as covered (3 of 8 on 30
        tuning scenes), so a policy pushed on at uncovered targets. The ray-cast path placed as
        miscalibrated cameras would (``raycast_misregistration``) is judged on a clean cast too."""
        if self.obs_mode != "camera":
            if self.visuals is not None and self.visuals.raycast_misregistration:
                return self._ray_caster()(self._built().data).depth  # the same reason: a misplaced view
            return maps.depth
        if self._occlusion_caster is None:
            self._occlusion_caster = RaycastHeightmapper(
                self._built().model, self.config.workspace, num_threads=self._raycast_threads
            )
        caster = self._occlusion_caster
        return caster(self._built().data).depth

    def target_view(self, depth: np.ndarray, target: int | None) -> tuple[np.ndarray, bool]:
        """The mask heightmap of ``target`` (of every object when ``mask_all_objects`` or no
        target) and whether the target is occluded in ``depth``."""
        world = self._built()
        ws = self.config.workspace
        if self.mask_all_objects or target is None:
            ids = [world.object_geom_ids[i] for i in world.active_objects()]
        else:
            ids = [world.object_geom_ids[target]] if world.active[target] else []
        geoms = np.concatenate(ids) if ids else np.zeros(0, dtype=int)
        mask = footprint_mask(ws, world.model, world.data, geoms) if geoms.size else np.zeros(ws.shape, np.uint8)
        occluded = False
        if target is not None and not self.mask_all_objects and world.active[target]:
            occluded = is_occluded(depth, mask, world.object_top(target), self.config.occlusion)
        return (mask > 0).astype(np.uint8), bool(occluded)

    def visible_fraction(self, maps, mask: np.ndarray, target: int | None) -> float | None:
        """Share of ``target``'s footprint ``mask`` where the target is the top surface, from
        the geom seen at each pixel of ``maps`` (``None`` without a target in the scene)."""
        world = self._built()
        if target is None or self.mask_all_objects or not world.active[target] or maps.geom_id is None:
            return None
        return visible_fraction(mask, maps.geom_id, world.object_geom_ids[target])

    def top_mask(self, maps, mask: np.ndarray, target: int | None) -> np.ndarray:
        """The pixels of the footprint ``mask`` where the target (every object, when
        ``mask_all_objects`` or no target) is the top surface in ``maps``: what a modal
        segmenter would give; empty while it is hidden."""
        world = self._built()
        if maps.geom_id is None:
            raise ValueError("the heightmaps carry no geom ids: the pixels where the target shows are unknown")
        if self.mask_all_objects or target is None:
            ids = [world.object_geom_ids[i] for i in world.active_objects()]
        else:
            ids = [world.object_geom_ids[target]] if world.active[target] else []
        geoms = np.concatenate(ids) if ids else np.zeros(0, dtype=int)
        return ((np.asarray(mask) > 0) & np.isin(maps.geom_id, geoms)).astype(np.uint8)

    def observe(
        self, target: int | None, motion: int = 0, *, top_mask: bool = False
    ) -> tuple[dict[str, np.ndarray], float | None]:
        """The observation of the current state for ``target`` (colour, depth, mask, the
        occlusion flag) after ``motion`` motions, and the target's visible fraction. With
        ``top_mask`` the observation also holds ``top_mask``: the mask's pixels where the target
        is the top surface (:meth:`top_mask`)."""
        hm = self.heightmaps(motion)
        mask, occluded = self.target_view(self._occlusion_depth(hm), target)
        obs = {
            "color": hm.color,
            "depth": hm.depth.astype(np.float32),
            "mask": mask,
            "occluded": np.array([int(occluded)], dtype=np.int8),
        }
        if top_mask:
            obs["top_mask"] = self.top_mask(hm, mask, target)
        return obs, self.visible_fraction(hm, mask, target)

    # ------------------------------------------------------------ try and undo
    def checkpoint(self) -> SimCheckpoint:
        """The world and the generator now, to :meth:`~SimCheckpoint.restore` later."""
        self._built()
        return SimCheckpoint(self)

    @contextmanager
    def trial(self) -> Iterator[EpisodeSim]:
        """Whatever runs inside is undone at the end: the world and the generator go back
        exactly (warm starts included). The one try-and-undo: ``try_primitive``, the env's
        ``try_step`` and the oracle's look-ahead use it."""
        checkpoint = self.checkpoint()
        try:
            yield self
        finally:
            checkpoint.restore()

    def try_primitive(
        self, primitive: str, rotation: int, row: int, col: int, depth: np.ndarray, target: int | None = None
    ) -> PrimitiveResult:
        """What running ``primitive`` at ``(rotation, row, col)`` does, with the world then
        put back exactly: what a planner with a perfect model of the physics can do."""
        executor = self.executor
        if executor is None:
            raise RuntimeError("no world yet: reset the env (or build a world) first")
        with self.trial():
            return executor.execute(primitive, rotation, row, col, depth, target)

    def _built(self) -> World:
        if self.world is None:
            raise RuntimeError("no world yet: reset the env (or build a world) first")
        return self.world

    def _ray_caster(self) -> RaycastHeightmapper:
        if self._raycaster is None:  # made with the world in ray-cast mode
            raise RuntimeError("no ray caster: the world is not built, or this is camera mode")
        return self._raycaster


def _same_assets(a: tuple[ObjectAsset, ...], b: tuple[ObjectAsset, ...]) -> bool:
    """The same objects in the same order (the same asset objects: a world compiles them)."""
    return len(a) == len(b) and all(x is y for x, y in zip(a, b))
