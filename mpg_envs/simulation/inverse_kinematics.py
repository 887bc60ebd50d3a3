"""Inverse kinematics of a site's pose by damped least squares, on MuJoCo's own functions.

The algorithm is dm-control's ``qpos_from_site_pose`` (``dm_control.utils.inverse_kinematics``,
Apache 2.0), step for step: the error is the site's position error plus its rotation error
(``mju_quat2Vel`` of target times inverse site orientation), the Jacobian is ``mj_jacSite``'s,
each update solves ``(J^T J + lambda I) dq = J^T e`` (``lambda`` only while the error is large,
least squares below), is capped in norm, and is applied with ``mj_integratePos`` followed by
``mj_fwdPosition``. The same operations in the same order give the same joint angles, bit for
bit, on the same MuJoCo; only MuJoCo's model and data are needed, no container around them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np


@dataclass(frozen=True)
class IKResult:
    """What a solve ended with.

    ``qpos`` is a copy of the model's whole ``qpos`` at the end; ``err_norm`` the position
    error's norm plus the weighted rotation error's norm (metres plus radians) measured
    before the last update; ``steps`` the index of the last iteration run; ``success``
    whether ``err_norm`` fell below the tolerance.
    """

    qpos: np.ndarray
    err_norm: float
    steps: int
    success: bool


def _checked_vector(name: str, value: np.ndarray, size: int) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != (size,) or not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be {size} finite numbers, got {np.asarray(value).tolist()!r}")
    return array


def damped_step(jac: np.ndarray, err: np.ndarray, regularization: float) -> np.ndarray:
    """Joint update ``dq`` for a task-space error ``err`` through the Jacobian ``jac``.

    Solves ``(J^T J + regularization * I) dq = J^T err``; with ``regularization == 0`` the
    least-squares solution of ``J^T J dq = J^T err`` (singular ``J`` allowed).
    """
    hess_approx = jac.T.dot(jac)
    joint_delta = jac.T.dot(err)
    if regularization > 0:
        hess_approx += np.eye(hess_approx.shape[0]) * regularization
        return np.linalg.solve(hess_approx, joint_delta)
    return np.linalg.lstsq(hess_approx, joint_delta, rcond=-1)[0]


def solve_site_pose(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    site_id: int,
    target_pos: np.ndarray,
    target_quat: np.ndarray,
    dof_indices: Sequence[int],
    *,
    tol: float = 1e-14,
    rot_weight: float = 1.0,
    regularization_threshold: float = 0.1,
    regularization_strength: float = 3e-2,
    max_update_norm: float = 2.0,
    progress_thresh: float = 20.0,
    max_steps: int = 100,
) -> IKResult:
    """Move ``data.qpos`` (in place) so site ``site_id`` reaches ``target_pos``/``target_quat``.

    Starts from the ``qpos`` in ``data``; only the degrees of freedom ``dof_indices`` move.
    Each iteration measures the error; below ``tol`` it stops with success. Otherwise it takes
    a damped least-squares step (damping ``regularization_strength`` while the error exceeds
    ``regularization_threshold``), scaled down to norm ``max_update_norm`` if longer, and stops
    without success when the error is over ``progress_thresh`` times the step (stuck in a local
    minimum) or after ``max_steps`` iterations. Joint limits are not considered.
    ``target_quat`` is a unit quaternion (w, x, y, z) in world coordinates.
    """
    if not 0 <= site_id < model.nsite:
        raise ValueError(f"site_id must be a site of the model (0 to {model.nsite - 1}), got {site_id}")
    dofs = [int(i) for i in dof_indices]
    if not dofs or any(not 0 <= i < model.nv for i in dofs):
        raise ValueError(f"dof_indices must be degrees of freedom of the model (0 to {model.nv - 1}), got {dofs}")
    if max_steps < 1 or tol <= 0:
        raise ValueError(f"max_steps must be at least 1 and tol positive, got {max_steps} and {tol}")
    target_pos = _checked_vector("target_pos", target_pos, 3)
    target_quat = _checked_vector("target_quat", target_quat, 4)

    jac = np.empty((6, model.nv))
    err = np.empty(6)
    jac_pos, jac_rot = jac[:3], jac[3:]
    err_pos, err_rot = err[:3], err[3:]
    update_nv = np.zeros(model.nv)
    site_xquat = np.empty(4)
    neg_site_xquat = np.empty(4)
    err_rot_quat = np.empty(4)

    mujoco.mj_fwdPosition(model, data)
    # Views: mj_fwdPosition updates them in place.
    site_xpos = data.site_xpos[site_id]
    site_xmat = data.site_xmat[site_id]

    steps = 0
    success = False
    err_norm = 0.0
    for step in range(max_steps):
        steps = step
        err_norm = 0.0
        err_pos[:] = target_pos - site_xpos
        err_norm += float(np.linalg.norm(err_pos))
        mujoco.mju_mat2Quat(site_xquat, site_xmat)
        mujoco.mju_negQuat(neg_site_xquat, site_xquat)
        mujoco.mju_mulQuat(err_rot_quat, target_quat, neg_site_xquat)
        mujoco.mju_quat2Vel(err_rot, err_rot_quat, 1)
        err_norm += float(np.linalg.norm(err_rot)) * rot_weight
        if err_norm < tol:
            success = True
            break
        mujoco.mj_jacSite(model, data, jac_pos, jac_rot, site_id)
        # Fancy indexing with a list, as dm-control does: the same memory layout, the same bits.
        jac_joints = jac[:, dofs]
        regularization = regularization_strength if err_norm > regularization_threshold else 0.0
        update_joints = damped_step(jac_joints, err, regularization)
        update_norm = np.linalg.norm(update_joints)
        # No progress: the error is large against the step (a zero step is no progress).
        if update_norm == 0 or err_norm / update_norm > progress_thresh:
            break
        if update_norm > max_update_norm:
            update_joints *= max_update_norm / update_norm
        update_nv[dofs] = update_joints
        mujoco.mj_integratePos(model, data.qpos, update_nv, 1)
        mujoco.mj_fwdPosition(model, data)
    return IKResult(qpos=data.qpos.copy(), err_norm=float(err_norm), steps=steps, success=success)
