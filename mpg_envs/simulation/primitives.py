"""The executor of the motion primitives, and the paper's three (Section III-B): move, push and grasp.

Each takes ``(rotation, row, col)`` on the heightmap grid plus the current depth
heightmap (for the local height ``h``) and runs the arm in simulation through its inverse
kinematics and the arm's own position actuators. Motions through free space above the clutter
(from the resting pose to above the action, back home, carrying a held object to its
place) are shortcut by setting the joint angles directly, since nothing can touch there;
every motion where contact can happen is simulated. A primitive's motion is looked up by name
(:mod:`mpg_envs.simulation.motions`); the paper's three are registered here.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import mujoco
import numpy as np

from mpg_envs.grid.primitive_specs import GRASP, MOVE, PUSH, primitive_spec
from mpg_envs.grid.workspace import check_pixel, check_rotation, pixel_to_world, rotation_angle
from mpg_envs.simulation.free_space import clutter_height, disc_offsets, free_spot
from mpg_envs.simulation.motion_memo import MotionMemo
from mpg_envs.simulation.motions import PrimitiveResult, motion_of, register_motion
from mpg_envs.simulation.robot import ArmIK, UnreachablePoseError, gripper_states
from mpg_envs.simulation.world import World, WorldCheckpoint


@dataclass(frozen=True)
class PrimitiveConfig:
    """Parameters of the primitives; distances in metres, speeds in m/s (paper defaults)."""

    grasp_depth: float = 0.04  # grasp and move descend this far below the local height
    grasp_min_height: float = 0.02  # ...but the fingertips' centre stays this high above the table
    push_length: float = 0.10
    push_depth: float = 0.01  # a push starts this far below h_p when h_p > 0 ...
    push_table_height: float = 0.02  # ... and at this height when the start is on the table
    push_min_height: float = 0.01  # the closed fingertips never aim below this (table contact)
    occupied_height: float = 0.005  # heights above this count as an object, below as table
    clearance: float = 0.04  # the pre-pose clears the clutter under the gripper by this much
    footprint_radius: float = 0.07  # radius of the gripper's footprint, for that clearance
    lift_height: float = 0.12  # lift this far above the pre-pose after grasping
    approach_speed: float = 0.35
    push_speed: float = 0.25
    lift_speed: float = 0.35
    waypoint_spacing: float = 0.04  # IK every this many metres along a straight motion
    close_max_steps: int = 300
    open_steps: int = 100
    hold_steps: int = 600  # at most this many steps for the servos to catch up at the end of a motion ...
    hold_tolerance: float = 0.003  # ... until the TCP is this close to where it was sent ...
    hold_stall_speed: float = 0.01  # ... or the arm stopped (every joint slower than this, rad/s: blocked or sagging)
    control_every: int = 5  # physics steps between servo set-point updates
    lifted_height: float = 0.05  # an object that rose this much with the gripper is grasped
    closed_margin: float = 0.05  # driver angle this far below fully closed = something between the pads
    place_margin: float = 0.02  # free space kept around a placed object
    place_clear_of_target: float = 0.06  # a placed object's centre stays this far from the target
    place_drop: float = 0.01  # a held object is released this far above the surface
    target_moved_distance: float = 0.01  # the target moved if its centre moved more than this ...
    target_moved_angle: float = 0.25  # ... or it turned more than this (radians)


GRASP_FAILURES = ("closed_empty", "not_lifted", "unreachable")
"""Why a grasp held nothing: the fingers closed fully on nothing (missed), or something was
between the pads but did not rise with them (slipped out, or pinned under another object),
or the arm could not reach the pose (nothing moved; see :meth:`PrimitiveExecutor.execute`)."""


class PrimitiveExecutor:
    """Runs a primitive's motion (move, push, grasp, or one registered later) on a :class:`World`.

    With ``memo`` (the default) a motion asked again from a state it was already run from
    is not simulated again: its end state and result are restored from a
    :class:`~mpg_envs.simulation.motion_memo.MotionMemo` (the same bits; a registered motion
    must, like the built-in ones, depend on nothing but the world and its arguments).
    Whoever resets ``world`` clears ``memo``.
    """

    def __init__(self, world: World, config: PrimitiveConfig = PrimitiveConfig(), ik: ArmIK | None = None, memo: bool = True):
        self.world = world
        self.memo: MotionMemo | None = MotionMemo() if memo else None
        self.config = config
        self.ik = ik if ik is not None else ArmIK(world.robot.config)
        self.gripper = gripper_states(world.robot.config)
        self._footprint_offsets = disc_offsets(config.footprint_radius, world.workspace.resolution)
        # A position servo (force kp (ctrl - q) - kv qdot) follows a set-point moving at v
        # kv/kp * v behind it; the set-point is led by that much so the arm is where the
        # motion says (velocity feed-forward, as an arm's own controller does).
        arm = world.robot.arm_actuators
        kp, kv = world.model.actuator_gainprm[arm, 0], -world.model.actuator_biasprm[arm, 2]
        self._servo_lag = np.where(kp > 0, kv / np.where(kp > 0, kp, 1.0), 0.0)

    # ------------------------------------------------------------------ API
    def execute(
        self, primitive: str, rotation: int, row: int, col: int, depth: np.ndarray, target: int | None = None
    ) -> PrimitiveResult:
        """Run ``primitive`` at rotation index ``rotation`` and pixel ``(row, col)``.

        ``depth`` is the current depth heightmap (metres above the table); ``target`` the
        index of the target object, whose motion is reported. A pose the arm cannot reach
        (:class:`~mpg_envs.simulation.robot.UnreachablePoseError`) puts the world back as it was and
        returns a result with ``unreachable`` set (``grasp_failure="unreachable"`` for grasp
        and move), so the env and the oracle's trials both carry on.
        """
        motion = motion_of(primitive)
        check_rotation(rotation)
        check_pixel(self.world.workspace, row, col)
        expected = self.world.workspace.shape
        if depth.shape != expected:
            raise ValueError(f"depth heightmap must have shape {expected}, got {depth.shape}")
        world = self.world
        start = time.perf_counter()
        memo = self.memo
        key = memo.key(world, primitive, rotation, row, col, depth, target) if memo is not None else b""
        if memo is not None:
            # Run from this very state before: its end state, restored, is the one it would reach.
            replayed = memo.replay(key, world)
            if replayed is not None:
                replayed.seconds = time.perf_counter() - start
                return replayed
        steps0, secs0, solves0 = world.counter.steps, world.counter.seconds, self.ik.solves
        target_pose = world.object_pose(target) if target is not None and world.active[target] else None
        checkpoint = WorldCheckpoint(world)
        try:
            result = motion(self, int(rotation), int(row), int(col), depth, target)
        except UnreachablePoseError:
            # An action inside the action space never ends in an exception: a pose the arm
            # cannot reach is a motion that did nothing (the world is put back).
            checkpoint.restore()
            result = self._unreachable(primitive, int(rotation), int(row), int(col))
        if target_pose is not None and target is not None:
            result.target_moved = target in result.removed_objects or self._moved(target, *target_pose)
        result.physics_steps = world.counter.steps - steps0
        result.physics_seconds = world.counter.seconds - secs0
        result.ik_solves = self.ik.solves - solves0
        result.seconds = time.perf_counter() - start
        if memo is not None and not result.unreachable:
            # (An unreachable pose was undone at once: nothing worth remembering.)
            memo.remember(key, result, WorldCheckpoint(world))
        return result

    def _unreachable(self, primitive: str, rotation: int, row: int, col: int) -> PrimitiveResult:
        """The result of a motion the arm could not reach (the world was put back)."""
        x, y = pixel_to_world(self.world.workspace, row, col)
        return PrimitiveResult(
            primitive,
            int(rotation),
            (int(row), int(col)),
            (float(x), float(y), 0.0),
            grasp_failure="unreachable" if primitive_spec(primitive).lifts else None,
            unreachable=True,
        )

    # ----------------------------------------------------------- primitives
    def grasp(self, rotation: int, row: int, col: int, depth: np.ndarray, target: int | None) -> PrimitiveResult:
        """Grasp's motion: descend open at the pixel, close, lift; what it holds leaves the scene.
        Unchecked: :meth:`execute` runs it."""
        x, y, z, z_pre, theta = self._grasp_pose(rotation, row, col, depth)
        result = PrimitiveResult(GRASP, rotation, (row, col), (x, y, z))
        held = self.pick(x, y, z, z_pre, theta, result)
        if held is not None:
            result.lifted, result.grasped_object = True, held
            self.world.remove_object(held)
            result.removed_objects = (held,)
        self.finish()
        return result

    def move(self, rotation: int, row: int, col: int, depth: np.ndarray, target: int | None) -> PrimitiveResult:
        """Move's motion: grasp as a grasp does, then put what it holds down at the most open spot
        (:func:`~mpg_envs.simulation.free_space.free_spot`; off the table when there is none).
        Unchecked: :meth:`execute` runs it."""
        x, y, z, z_pre, theta = self._grasp_pose(rotation, row, col, depth)
        result = PrimitiveResult(MOVE, rotation, (row, col), (x, y, z))
        held = self.pick(x, y, z, z_pre, theta, result)
        if held is not None:
            result.lifted, result.grasped_object = True, held
            spot = free_spot(self.world, held, target, self.config.place_margin, self.config.place_clear_of_target)
            if spot is None:
                # Nowhere free in the workspace: set it aside off the table.
                self.world.remove_object(held)
                result.removed_objects = (held,)
            else:
                self._place(held, spot, theta)
                result.placed_object = held
        self.finish()
        return result

    def push(self, rotation: int, row: int, col: int, depth: np.ndarray, target: int | None) -> PrimitiveResult:
        """Push's motion: the closed fingers slide ``push_length`` along the rotation's direction.
        Unchecked: :meth:`execute` runs it."""
        cfg, ws = self.config, self.world.workspace
        x, y = pixel_to_world(ws, row, col)
        h = float(depth[row, col])
        z = max(h - cfg.push_depth, cfg.push_min_height) if h > cfg.occupied_height else cfg.push_table_height
        direction = rotation_angle(rotation)
        end = np.array([x + cfg.push_length * math.cos(direction), y + cfg.push_length * math.sin(direction)])
        end = np.clip(end, (ws.x_min, ws.y_min), (ws.x_max, ws.y_max))
        # The closed fingers present their broad side to the push.
        theta = direction + math.pi / 2
        result = PrimitiveResult(PUSH, rotation, (row, col), (x, y, z))
        z_pre = self.pre_height(depth, row, col, z)
        q = self.teleport((x, y, z_pre), theta, closed=True)
        q = self.linear((x, y, z_pre), (x, y, z), theta, q, cfg.approach_speed)
        q = self.linear((x, y, z), (end[0], end[1], z), theta, q, cfg.push_speed)
        self.linear((end[0], end[1], z), (end[0], end[1], z_pre), theta, q, cfg.lift_speed)
        self.finish()
        return result

    # -------------------------------------------------------------- helpers
    def _grasp_pose(self, rotation: int, row: int, col: int, depth: np.ndarray):
        cfg = self.config
        x, y = pixel_to_world(self.world.workspace, row, col)
        z = max(float(depth[row, col]) - cfg.grasp_depth, cfg.grasp_min_height)
        return x, y, z, self.pre_height(depth, row, col, z), rotation_angle(rotation)

    # ------------------------------------------------------- motion pieces
    def pre_height(self, depth: np.ndarray, row: int, col: int, z: float) -> float:
        """The height of the pose above pixel ``(row, col)`` a motion descends from to ``z``:
        clear of the highest clutter under the gripper's footprint by ``config.clearance``."""
        return max(clutter_height(depth, row, col, self._footprint_offsets), z) + self.config.clearance

    def pick(self, x: float, y: float, z: float, z_pre: float, theta: float, result: PrimitiveResult) -> int | None:
        """Descend open, close, lift; the index of the object held afterwards, if any (else
        ``result.grasp_failure`` says why)."""
        cfg, world = self.config, self.world
        q = self.teleport((x, y, z_pre), theta, closed=False)
        q = self.linear((x, y, z_pre), (x, y, z), theta, q, cfg.approach_speed)
        heights = {i: world.object_position(i)[2] for i in world.active_objects()}
        self._actuate_gripper(closed=True)
        z_lift = z_pre + cfg.lift_height
        self.linear((x, y, z), (x, y, z_lift), theta, q, cfg.lift_speed)
        held = self._held_object(heights)
        if held is None:
            closed = world.robot.driver_angle(world.data) > self.gripper.closed_driver_angle - cfg.closed_margin
            result.grasp_failure = "closed_empty" if closed else "not_lifted"
        return held

    def _held_object(self, heights_before: dict[int, float]) -> int | None:
        world, cfg = self.world, self.config
        if world.robot.driver_angle(world.data) > self.gripper.closed_driver_angle - cfg.closed_margin:
            return None  # the fingers closed fully: nothing between them
        touching = {
            int(world.object_of_geom(o))
            for _, o in world.contacts_between(world.robot.gripper_geom_ids, np.concatenate(world.object_geom_ids))
        }
        lifted = [
            i for i in touching if i >= 0 and world.object_position(i)[2] - heights_before.get(i, np.inf) > cfg.lifted_height
        ]
        if not lifted:
            return None
        # Of several lifted objects (one resting on another), the pads hold the lowest.
        return min(lifted, key=lambda i: world.object_position(i)[2])

    def _place(self, held: int, spot: tuple[float, float], theta: float) -> None:
        """Carry the held object to above ``spot`` (free space: shortcut), lower it, release."""
        cfg, world = self.config, self.world
        data = world.data
        tcp = world.robot.tcp_site
        # Hold the object's pose fixed relative to the TCP through the shortcut.
        r_tcp = data.site_xmat[tcp].reshape(3, 3).copy()
        p_tcp = data.site_xpos[tcp].copy()
        pos, quat = world.object_pose(held)
        r_obj = np.empty(9)
        mujoco.mju_quat2Mat(r_obj, quat)
        rel_pos = r_tcp.T @ (pos - p_tcp)
        rel_rot = r_tcp.T @ r_obj.reshape(3, 3)
        bottom = float(world.object_vertices(held)[:, 2].min())
        hang = p_tcp[2] - bottom  # TCP height above the object's lowest point
        z_carry = p_tcp[2]
        z_release = hang + cfg.place_drop
        gripper_qpos = world.robot.gripper_qpos(data)
        z_carry, q = self._carry_pose(spot, theta, z_carry, z_release)
        world.robot.teleport_arm(data, q)
        world.robot.set_gripper(data, gripper_qpos, world.robot.config.gripper_closed_ctrl)
        mujoco.mj_kinematics(world.model, data)
        r_new = data.site_xmat[tcp].reshape(3, 3)
        new_quat = np.empty(4)
        mujoco.mju_mat2Quat(new_quat, (r_new @ rel_rot).ravel())
        world.set_object_pose(held, data.site_xpos[tcp] + r_new @ rel_pos, new_quat)
        world.forward()
        q = self.linear((spot[0], spot[1], z_carry), (spot[0], spot[1], z_release), theta, q, cfg.approach_speed)
        self._actuate_gripper(closed=False)
        self.linear((spot[0], spot[1], z_release), (spot[0], spot[1], z_carry), theta, q, cfg.lift_speed)

    def _carry_pose(
        self, spot: tuple[float, float], theta: float, z_carry: float, z_release: float
    ) -> tuple[float, np.ndarray]:
        """The carry height above ``spot`` and its joint angles: the height the object was lifted
        to, or lower (5 cm at a time, not below 5 cm above the release height) where that is
        out of the arm's reach (a high lift over a far corner of the workspace)."""
        seed = self.world.robot.arm_qpos(self.world.data)
        z = z_carry
        while True:
            try:
                return z, self.ik.solve((spot[0], spot[1], z), theta, seed)
            except UnreachablePoseError:
                if z - 0.05 < z_release + 0.05:
                    raise
                z -= 0.05

    def teleport(self, position, theta: float, closed: bool) -> np.ndarray:
        """Set the arm at the pose ``position`` (TCP) turned ``theta``, fingers closed or open
        (a free-space shortcut, nothing simulated); its joint angles."""
        world = self.world
        q = self.ik.solve(position, theta, np.asarray(world.robot.config.home))
        world.robot.teleport_arm(world.data, q)
        qpos = self.gripper.closed_qpos if closed else self.gripper.open_qpos
        cfg = world.robot.config
        world.robot.set_gripper(world.data, qpos, cfg.gripper_closed_ctrl if closed else cfg.gripper_open_ctrl)
        world.forward()
        return q

    def linear(self, start, end, theta: float, q_start: np.ndarray, speed: float) -> np.ndarray:
        """Move the TCP along a straight line through IK waypoints, simulated."""
        cfg, world = self.config, self.world
        start, end = np.asarray(start, float), np.asarray(end, float)
        length = float(np.linalg.norm(end - start))
        n_wp = max(1, math.ceil(length / cfg.waypoint_spacing))
        q_prev = np.asarray(q_start, float)
        dt = world.model.opt.timestep * cfg.control_every
        for k in range(1, n_wp + 1):
            q_next = self.ik.solve(start + (end - start) * k / n_wp, theta, q_prev)
            chunks = max(1, math.ceil(length / n_wp / speed / dt))
            lead = self._servo_lag * (q_next - q_prev) / (chunks * dt)
            for c in range(1, chunks + 1):
                world.data.ctrl[world.robot.arm_actuators] = q_prev + (q_next - q_prev) * c / chunks + lead
                world.step(cfg.control_every)
            q_prev = q_next
        self._hold(q_prev, end)
        return q_prev

    def _hold(self, q: np.ndarray, position: np.ndarray) -> None:
        """Let the servos settle on ``q`` until the TCP is at ``position`` or the arm stops (bounded).

        The arm's position servos lag a moving set-point by about their damping over their
        stiffness (0.2 s on the UR5e: centimetres at the approach speed), so a motion is only
        over when the arm has caught up; closing the fingers earlier closes them centimetres
        above where the grasp was aimed.
        """
        cfg, world = self.config, self.world
        robot, data = world.robot, world.data
        data.ctrl[robot.arm_actuators] = q
        for _ in range(max(1, cfg.hold_steps // cfg.control_every)):
            if np.linalg.norm(robot.tcp_position(data) - position) < cfg.hold_tolerance:
                break
            if np.abs(data.qvel[robot.arm_dof_adr]).max() < cfg.hold_stall_speed:
                break
            world.step(cfg.control_every)

    def _actuate_gripper(self, closed: bool) -> None:
        cfg, world = self.config, self.world
        robot = world.robot
        world.data.ctrl[robot.gripper_actuator] = (
            robot.config.gripper_closed_ctrl if closed else robot.config.gripper_open_ctrl
        )
        cap = cfg.close_max_steps if closed else cfg.open_steps
        used, last = 0, robot.driver_angle(world.data)
        while used < cap:
            world.step(cfg.control_every)
            used += cfg.control_every
            angle = robot.driver_angle(world.data)
            # Stop once the fingers stopped moving (closed on something, fully closed, or open).
            if used >= 4 * cfg.control_every and abs(angle - last) < 1e-4:
                break
            last = angle

    def finish(self) -> None:
        """Arm back home (free-space shortcut), gripper open, let the scene come to rest."""
        world = self.world
        cfg = world.robot.config
        world.robot.teleport_arm(world.data, np.asarray(cfg.home))
        world.robot.set_gripper(world.data, self.gripper.open_qpos, cfg.gripper_open_ctrl)
        world.forward()
        world.settle()

    def _moved(self, i: int, pos: np.ndarray, quat: np.ndarray) -> bool:
        new_pos, new_quat = self.world.object_pose(i)
        angle = 2 * math.acos(min(1.0, abs(float(np.dot(quat, new_quat)))))
        return bool(
            np.linalg.norm(new_pos - pos) > self.config.target_moved_distance or angle > self.config.target_moved_angle
        )


Primitives = PrimitiveExecutor
"""The executor's former name (kept: it is public)."""

for _name, _motion in ((MOVE, PrimitiveExecutor.move), (PUSH, PrimitiveExecutor.push), (GRASP, PrimitiveExecutor.grasp)):
    register_motion(_name, _motion)
