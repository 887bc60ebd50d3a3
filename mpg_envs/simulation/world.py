"""The simulated world: arena + robot + objects, composed with ``MjSpec`` and stepped.

``World`` owns one compiled MuJoCo model and its data. It knows which bodies are the
objects, drops them and steps until they are at rest, removes grasped objects from the
scene, and counts the physics it runs (steps and wall time inside ``mj_step``) so the
benchmarks can tell simulation from overhead.
"""

from __future__ import annotations

import functools
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import mujoco
import numpy as np

from mpg_envs.grid.workspace import Workspace
from mpg_envs.simulation.mujoco_version import constraint_jacobian
from mpg_envs.simulation.objects import ObjectAsset, add_object_body
from mpg_envs.simulation.robot import Robot, RobotConfig, robot_spec

ROBOT_PREFIX = "robot/"


def arena_path() -> str:
    """Path of the arena MJCF: ``mpg_envs/xml/arena.xml`` in an installed wheel, the top-level
    ``xml/arena.xml`` in a source checkout (editable installs don't map data-only folders)."""
    try:
        shipped = resources.files("mpg_envs.xml").joinpath("arena.xml")
        if shipped.is_file():
            return str(shipped)
    except ModuleNotFoundError:
        pass
    checkout = Path(__file__).resolve().parents[2] / "xml" / "arena.xml"  # mpg_envs/simulation/world.py -> the checkout
    if not checkout.is_file():
        raise FileNotFoundError(f"arena MJCF not found in the package nor at {checkout}")
    return str(checkout)


@functools.lru_cache(maxsize=4)
def _arena_with_robot(robot: RobotConfig, visual: bool) -> mujoco.MjSpec:
    """The arena with the robot attached (kept: :class:`World` adds its objects to a copy)."""
    spec = mujoco.MjSpec.from_file(arena_path())
    with warnings.catch_warnings():
        # The arena already carries the gripper's impratio/cone; the attach only notices.
        warnings.filterwarnings("ignore", message="Attach conflict")
        spec.attach(robot_spec(robot, visual=visual), site=spec.site("robot_mount"), prefix=ROBOT_PREFIX)
    return spec


@dataclass(frozen=True)
class PhysicsConfig:
    """Simulation settings; the defaults hold a closed 2F-85 grip and settle piles quickly."""

    timestep: float = 0.002
    # Below these speeds every object counts as at rest (m/s, rad/s).
    rest_linear_velocity: float = 0.01
    rest_angular_velocity: float = 0.2
    # Cap on settling after one drop or one primitive (steps), so nothing can hang.
    settle_max_steps: int = 500
    # Steps between checks of the rest condition (a check costs a few microseconds).
    settle_check_every: int = 10
    drop_height: float = 0.15
    # Objects whose centre leaves this box count as having left the room (metres).
    room_half_extent: float = 2.0


@dataclass
class PhysicsCounter:
    """Physics work done since the last reset of the counter."""

    steps: int = 0
    seconds: float = 0.0

    def reset(self) -> None:
        self.steps = 0
        self.seconds = 0.0


class World:
    """A compiled scene holding the robot and ``len(objects)`` objects.

    Objects are numbered in the order given. An object can be *active* (in the scene) or
    *removed* (grasped and taken away): removed objects stop colliding and float,
    compensated for gravity, far below the floor, where nothing sees them.

    ``robot_visual=False`` compiles the robot without its visual-only meshes (same
    dynamics, several times faster to build; the robot then renders as its collision
    shapes): for worlds nothing renders.
    """

    PARK_DEPTH = -10.0

    def __init__(
        self,
        objects: Sequence[ObjectAsset],
        workspace: Workspace = Workspace(),
        robot: RobotConfig = RobotConfig(),
        physics: PhysicsConfig = PhysicsConfig(),
        extra_spec_hook: Callable[[mujoco.MjSpec], object] | None = None,
        robot_visual: bool = True,
    ):
        self.workspace = workspace
        self.physics = physics
        self.assets = list(objects)
        spec = _arena_with_robot(robot, robot_visual).copy()  # a copy: parsing and attaching cost more than objects
        spec.option.timestep = physics.timestep
        # MuJoCo's choice, except on a release whose sparse solver diverges (mujoco_version).
        spec.option.jacobian = constraint_jacobian()
        for i, asset in enumerate(self.assets):
            pos = (self.workspace.center[0], self.workspace.center[1], self.PARK_DEPTH - i)
            body = add_object_body(spec, spec.worldbody, asset, name=f"object{i}", pos=pos)
            # A tiny non-zero value makes MuJoCo keep gravity compensation switchable at run
            # time (it is compiled out when every body has 0); 1e-12 g changes nothing.
            body.gravcomp = 1e-12
        if extra_spec_hook is not None:
            extra_spec_hook(spec)
        self.spec = spec
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self.robot = Robot(self.model, ROBOT_PREFIX, robot)
        self.counter = PhysicsCounter()

        m = self.model
        self.object_body_ids = np.array([m.body(f"object{i}").id for i in range(len(self.assets))], dtype=int)
        self.object_qpos_adr = np.array([m.jnt_qposadr[m.body_jntadr[b]] for b in self.object_body_ids], dtype=int)
        self.object_dof_adr = np.array([m.jnt_dofadr[m.body_jntadr[b]] for b in self.object_body_ids], dtype=int)
        # A body's geoms are contiguous in a compiled model (body_geomadr, body_geomnum).
        self.object_geom_ids = [
            np.arange(m.body_geomadr[b], m.body_geomadr[b] + m.body_geomnum[b]) for b in self.object_body_ids
        ]
        self._geom_owner = np.full(m.ngeom, -1, dtype=int)
        for i, geoms in enumerate(self.object_geom_ids):
            self._geom_owner[geoms] = i
        self._geom_contype = m.geom_contype.copy()
        self._geom_conaffinity = m.geom_conaffinity.copy()
        self.active = np.zeros(len(self.assets), dtype=bool)
        self.reset()

    # ------------------------------------------------------------------ state
    @property
    def num_objects(self) -> int:
        return len(self.assets)

    def reset(self) -> None:
        """Robot at home, gripper open, every object removed (parked)."""
        mujoco.mj_resetData(self.model, self.data)
        self.robot.teleport_arm(self.data, np.asarray(self.robot.config.home))
        self.data.ctrl[self.robot.gripper_actuator] = self.robot.config.gripper_open_ctrl
        for i in range(self.num_objects):
            self.remove_object(i)
        mujoco.mj_forward(self.model, self.data)
        self.counter.reset()

    def object_of_geom(self, geom_id: int | np.ndarray) -> int | np.ndarray:
        """Object index owning each geom id (-1 for the table, robot or none)."""
        geom_id = np.asarray(geom_id)
        owner = np.where(geom_id >= 0, self._geom_owner[np.clip(geom_id, 0, None)], -1)
        return owner if owner.ndim else int(owner)

    def object_position(self, i: int) -> np.ndarray:
        return self.data.xpos[self.object_body_ids[i]].copy()

    def object_pose(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        adr = self.object_qpos_adr[i]
        return self.data.qpos[adr : adr + 3].copy(), self.data.qpos[adr + 3 : adr + 7].copy()

    def object_vertices(self, i: int) -> np.ndarray:
        """World coordinates of every vertex of object ``i`` at its current pose (N, 3)."""
        body = self.object_body_ids[i]
        local = self.assets[i].vertices
        return self.data.xpos[body] + local @ self.data.xmat[body].reshape(3, 3).T

    def object_top(self, i: int) -> float:
        """Height of the highest point of object ``i`` above the table."""
        return float(self.object_vertices(i)[:, 2].max())

    def set_object_pose(self, i: int, position: Sequence[float] | np.ndarray, quat: Sequence[float] | np.ndarray) -> None:
        """Place object ``i`` (making it active) at rest at a pose."""
        adr, dof = self.object_qpos_adr[i], self.object_dof_adr[i]
        self.data.qpos[adr : adr + 3] = position
        q = np.asarray(quat, dtype=float)
        norm = np.linalg.norm(q)
        # A quaternion read from the simulation is unit to rounding: keep its bits, so a saved
        # scene restores bit-identical observations; anything else is normalised.
        self.data.qpos[adr + 3 : adr + 7] = q if abs(norm - 1.0) < 1e-12 else q / norm
        self.data.qvel[dof : dof + 6] = 0.0
        self._set_active(i, True)

    def remove_object(self, i: int) -> None:
        """Take object ``i`` out of the scene: no collisions, parked far below the floor."""
        adr, dof = self.object_qpos_adr[i], self.object_dof_adr[i]
        self.data.qpos[adr : adr + 3] = (self.workspace.center[0] + 0.5 * i, self.workspace.center[1], self.PARK_DEPTH)
        self.data.qpos[adr + 3 : adr + 7] = (1.0, 0.0, 0.0, 0.0)
        self.data.qvel[dof : dof + 6] = 0.0
        self._set_active(i, False)

    def _set_active(self, i: int, active: bool) -> None:
        geoms = self.object_geom_ids[i]
        self.model.geom_contype[geoms] = self._geom_contype[geoms] if active else 0
        self.model.geom_conaffinity[geoms] = self._geom_conaffinity[geoms] if active else 0
        self.model.body_gravcomp[self.object_body_ids[i]] = 1e-12 if active else 1.0
        # Removed objects are hidden from the heightmap ray casts (groups 0-1) too.
        self.model.geom_group[geoms] = 1 if active else 5
        self.active[i] = active

    def active_objects(self) -> np.ndarray:
        return np.flatnonzero(self.active)

    # ---------------------------------------------------------------- physics
    def step(self, nstep: int = 1) -> None:
        """Advance the physics ``nstep`` steps, counting them and the time they take."""
        start = time.perf_counter()
        mujoco.mj_step(self.model, self.data, nstep=nstep)
        self.counter.seconds += time.perf_counter() - start
        self.counter.steps += nstep

    def forward(self) -> None:
        mujoco.mj_forward(self.model, self.data)

    @contextmanager
    def stepping(self, timestep: float | None) -> Iterator[World]:
        """Step with ``timestep`` (seconds; ``None``: the physics' own) inside the block, then
        with the physics' own again: for motions only the end state of which matters (a drop)."""
        if timestep is None or timestep == self.model.opt.timestep:
            yield self
            return
        if not 0 < timestep <= 0.01:
            raise ValueError(f"timestep must be in (0, 0.01] s, got {timestep!r}")
        own = self.model.opt.timestep
        self.model.opt.timestep = timestep
        try:
            yield self
        finally:
            self.model.opt.timestep = own

    def objects_at_rest(self) -> bool:
        """Whether every active object moves slower than the rest thresholds."""
        idx = self.active_objects()
        if idx.size == 0:
            return True
        dof = self.object_dof_adr[idx][:, None] + np.arange(6)
        vel = self.data.qvel[dof]
        return bool(
            np.all(np.linalg.norm(vel[:, :3], axis=1) < self.physics.rest_linear_velocity)
            and np.all(np.linalg.norm(vel[:, 3:], axis=1) < self.physics.rest_angular_velocity)
        )

    def settle(self, max_steps: int | None = None) -> int:
        """Step until every object is at rest or the cap is hit; returns the steps used."""
        cap = self.physics.settle_max_steps if max_steps is None else max_steps
        every = self.physics.settle_check_every
        used = 0
        while used < cap:
            n = min(every, cap - used)
            self.step(n)
            used += n
            if self.objects_at_rest():
                break
        # mj_step leaves poses (xpos, geom_xpos) one step behind qpos; recompute them so what
        # is observed is exactly the state that would be saved and restored.
        self.forward()
        return used

    def drop_object(
        self,
        i: int,
        xy: Sequence[float] | np.ndarray,
        quat: Sequence[float] | np.ndarray,
        height: float | None = None,
        max_steps: int | None = None,
    ) -> int:
        """Drop object ``i`` from ``height`` above whatever is below ``xy`` and let it settle
        (at most ``max_steps`` steps; ``None``: the physics' ``settle_max_steps``).

        The drop height is measured from the object's lowest point to the highest point of
        the scene under its footprint, so it never starts inside another object.
        """
        height = self.physics.drop_height if height is None else height
        self.set_object_pose(i, (xy[0], xy[1], 0.0), quat)
        mujoco.mj_kinematics(self.model, self.data)
        verts = self.object_vertices(i)
        below = self._scene_top_near(verts[:, :2], exclude=i)
        lift = height + below - verts[:, 2].min()
        self.set_object_pose(i, (xy[0], xy[1], lift), quat)
        mujoco.mj_forward(self.model, self.data)
        return self.settle(max_steps)

    def _scene_top_near(self, xy: np.ndarray, exclude: int) -> float:
        lo, hi = xy.min(axis=0) - 0.01, xy.max(axis=0) + 0.01
        top = 0.0
        for j in self.active_objects():
            if j == exclude:
                continue
            v = self.object_vertices(j)
            if _boxes_overlap(v[:, :2], lo, hi):
                top = max(top, float(v[:, 2].max()))
        return top

    # ----------------------------------------------------------------- checks
    def objects_outside_workspace(self) -> np.ndarray:
        """Active objects whose centre of mass has left the workspace footprint or fallen off the table."""
        idx = self.active_objects()
        if idx.size == 0:
            return idx
        pos = self.data.xpos[self.object_body_ids[idx]]
        inside = self.workspace.contains_xy(pos[:, 0], pos[:, 1]) & (pos[:, 2] > -0.02)
        return idx[~np.asarray(inside)]

    def objects_off_table(self) -> np.ndarray:
        """Active objects that fell below the table top."""
        idx = self.active_objects()
        pos = self.data.xpos[self.object_body_ids[idx]]
        return idx[pos[:, 2] < -0.02]

    def objects_out_of_room(self) -> np.ndarray:
        """Active objects whose position is not finite or beyond the room box."""
        idx = self.active_objects()
        pos = self.data.xpos[self.object_body_ids[idx]]
        bad = ~np.all(np.isfinite(pos), axis=1) | np.any(np.abs(pos) > self.physics.room_half_extent, axis=1)
        return idx[bad]

    def contacts_between(self, geoms_a: np.ndarray, geoms_b: np.ndarray) -> list[tuple[int, int]]:
        """Active contacts ``(geom_a, geom_b)`` between the two geom sets."""
        a, b = set(int(g) for g in geoms_a), set(int(g) for g in geoms_b)
        pairs = []
        for c in self.data.contact[: self.data.ncon]:
            g1, g2 = int(c.geom1), int(c.geom2)
            if g1 in a and g2 in b:
                pairs.append((g1, g2))
            elif g2 in a and g1 in b:
                pairs.append((g2, g1))
        return pairs

    def objects_left(self) -> int:
        """Objects still in the scene and inside the workspace."""
        return int(self.active.sum() - len(self.objects_outside_workspace()))

    def take_warnings(self) -> dict[str, int]:
        """MuJoCo's warning counts since the last call (then cleared, so each call's are its own)."""
        counts = self.warnings_raised()
        for w in self.data.warning:
            w.number = 0
        return counts

    def remove_strays(self) -> np.ndarray:
        """Take out of the scene the objects an unstable contact threw out of the room (so they
        cannot poison later steps); returns their indices."""
        bad = self.objects_out_of_room()
        for i in bad:
            self.remove_object(int(i))
        if len(bad):
            self.forward()
        return bad

    def warnings_raised(self) -> dict[str, int]:
        """MuJoCo warnings counted in ``data.warning`` (nonzero means the simulation struggled)."""
        out = {}
        for name, member in mujoco.mjtWarning.__members__.items():
            if name != "mjNWARNING" and int(self.data.warning[int(member)].number):
                out[name] = int(self.data.warning[int(member)].number)
        return out


class WorldCheckpoint:
    """The state of a world at one moment, to return to."""

    def __init__(self, world: World):
        self.world = world
        self._data = mujoco.MjData(world.model)
        mujoco.mj_copyData(self._data, world.model, world.data)
        self._active = world.active.copy()
        self._counter = (world.counter.steps, world.counter.seconds)

    def restore(self) -> None:
        """Put the world back as it was when the checkpoint was made."""
        world = self.world
        for i in np.flatnonzero(world.active != self._active):
            if self._active[i]:
                pos, quat = self._pose(int(i))
                world.set_object_pose(int(i), pos, quat)  # back in the scene (collisions, ray casts)
            else:
                world.remove_object(int(i))
        mujoco.mj_copyData(world.data, world.model, self._data)
        world.counter.steps, world.counter.seconds = self._counter

    def _pose(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        adr = self.world.object_qpos_adr[i]
        return self._data.qpos[adr : adr + 3].copy(), self._data.qpos[adr + 3 : adr + 7].copy()


def _boxes_overlap(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    plo, phi = points.min(axis=0), points.max(axis=0)
    return bool(np.all(plo <= hi) and np.all(phi >= lo))
