"""The damped least-squares IK on MuJoCo's own functions: hand-checked cases and the arm's
solutions as dm-control's ``qpos_from_site_pose`` gave them."""

import math
import subprocess
import sys

import mujoco
import numpy as np
import pytest

from mpg_envs.simulation.inverse_kinematics import damped_step, solve_site_pose
from mpg_envs.simulation.robot import TCP_SITE, ArmIK, RobotConfig, UnreachablePoseError, robot_spec, tcp_quat

# A body on a slide joint along world x, a site at its origin: the site reaches x = q only.
SLIDE = """
<mujoco>
  <worldbody>
    <body name="carriage">
      <joint name="slide" type="slide" axis="1 0 0" range="-1 1"/>
      <geom type="box" size="0.05 0.05 0.05"/>
      <site name="tip"/>
    </body>
  </worldbody>
</mujoco>
"""
IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def slide():
    model = mujoco.MjModel.from_xml_string(SLIDE)
    return model, mujoco.MjData(model)


def test_a_damped_step_solves_the_normal_equations_by_hand():
    # J = I: the least-squares step is the error itself; damping 1 halves it ((1 + 1) dq = e).
    np.testing.assert_allclose(damped_step(np.eye(2), np.array([1.0, 2.0]), 0.0), [1.0, 2.0])
    np.testing.assert_allclose(damped_step(np.eye(2), np.array([1.0, 2.0]), 1.0), [0.5, 1.0])
    # A singular J = diag(2, 0): the minimum-norm least-squares step moves only the first joint.
    np.testing.assert_allclose(damped_step(np.diag([2.0, 0.0]), np.array([3.0, 5.0]), 0.0), [1.5, 0.0], atol=1e-15)


def test_a_reachable_pose_is_solved_to_tolerance(slide):
    model, data = slide
    data.qpos[:] = 0.0
    result = solve_site_pose(model, data, model.site("tip").id, np.array([0.3, 0.0, 0.0]), IDENTITY, [0], tol=1e-10)
    assert result.success and result.err_norm < 1e-10
    assert result.qpos[0] == pytest.approx(0.3, abs=1e-10)
    assert data.qpos[0] == result.qpos[0]  # solved in place


def test_an_unreachable_pose_is_reported_as_not_converged(slide):
    model, data = slide
    data.qpos[:] = 0.0
    # 0.1 m off the slide's line: the error never falls under 0.1, so every step is damped
    # (J = 1: dq = dx / 1.03, leaving dx * 0.03 / 1.03), and the third step, 0.3 * (0.03 / 1.03)^2
    # / 1.03, is under a twentieth of the error: no progress, the solve stops there.
    result = solve_site_pose(model, data, model.site("tip").id, np.array([0.3, 0.1, 0.0]), IDENTITY, [0], tol=1e-10)
    assert not result.success and result.steps == 2
    assert result.err_norm == pytest.approx(math.hypot(0.3 * (0.03 / 1.03) ** 2, 0.1), rel=1e-12)
    assert result.qpos[0] == pytest.approx(0.3 - 0.3 * (0.03 / 1.03) ** 2, rel=1e-12)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"target_pos": np.zeros(2)}, "target_pos must be 3 finite numbers"),
        ({"target_quat": np.array([1.0, 0.0, 0.0, math.nan])}, "target_quat must be 4 finite numbers"),
        ({"site_id": 3}, r"site_id must be a site of the model \(0 to 0\)"),
        ({"dof_indices": [1]}, r"dof_indices must be degrees of freedom of the model \(0 to 0\)"),
        ({"max_steps": 0}, "max_steps must be at least 1"),
    ],
)
def test_bad_input_is_named(slide, change, message):
    model, data = slide
    args = {"site_id": 0, "target_pos": np.zeros(3), "target_quat": IDENTITY, "dof_indices": [0]} | change
    max_steps = args.pop("max_steps", 100)
    with pytest.raises(ValueError, match=message):
        solve_site_pose(model, data, **args, max_steps=max_steps)


@pytest.fixture(scope="module")
def ik():
    return ArmIK()


HOME = np.asarray(RobotConfig().home)
# Arm joint angles dm-control 1.0.50's qpos_from_site_pose gave (MuJoCo 3.17, tol 1e-7), wrapped
# to the seed as ArmIK wraps them: (TCP position, closing angle, seed) -> joint angles.
DM_CONTROL_SOLUTIONS = [
    ((0.5, 0.0, 0.05), 0.3, HOME,
     [-3.412909143492104, -1.3376590870203466, 2.0999316101218772, -2.3330688499015944, -1.570796326810665, -2.1421128166980035]),
    ((0.35, -0.2, 0.2), -1.2, HOME,
     [-3.9995997786828132, -1.7897797591858977, 2.106396524506737, -1.887413092115527, -1.57079632679455, -1.2288034518879258]),
    ((0.7, 0.2, 0.02), 2.5, HOME + np.array([0.3, -0.2, 0.1, 0.2, -0.3, 0.4]),
     [-3.0484116425518133, -0.8461880286598329, 1.397772422191209, -2.122380720327039, -1.5707963267968807, 2.305569991422642]),
]


@pytest.mark.parametrize("position, theta, seed, expected", DM_CONTROL_SOLUTIONS)
def test_the_arm_gets_the_joint_angles_dm_control_gave(ik, position, theta, seed, expected):
    q = ik.solve(np.array(position), theta, seed)
    if mujoco.__version__.split(".")[0] == "3":
        assert q.tolist() == expected  # bit for bit: the same operations in the same order
    else:
        np.testing.assert_allclose(q, expected, atol=1e-9)


def test_the_arm_reaches_the_pose_and_refuses_one_out_of_reach(ik):
    q = ik.solve(np.array([0.45, 0.1, 0.08]), 0.7)
    model = robot_spec().compile()
    data = mujoco.MjData(model)
    data.qpos[:6] = q
    mujoco.mj_kinematics(model, data)
    site = model.site(TCP_SITE).id
    np.testing.assert_allclose(data.site_xpos[site], [0.45, 0.1, 0.08], atol=1e-7)
    np.testing.assert_allclose(data.site_xmat[site].reshape(3, 3)[:, 1], [math.cos(0.7), math.sin(0.7), 0.0], atol=1e-7)
    with pytest.raises(UnreachablePoseError, match=r"IK failed for TCP position \[2.0, 0.0, 0.1\]"):
        ik.solve(np.array([2.0, 0.0, 0.1]), 0.0)


def test_importing_the_envs_imports_no_dm_control():
    code = "import mpg_envs, sys; assert not any(m.startswith('dm_control') for m in sys.modules)"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
