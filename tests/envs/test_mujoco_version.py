"""The MuJoCo release a world runs on: MuJoCo 4.0.0's sparse solver is avoided, every other
release keeps MuJoCo's own choice (so 3.x results stay bit for bit)."""

import mujoco

from mpg_envs.simulation.mujoco_version import constraint_jacobian
from mpg_envs.simulation.world import World


def test_only_the_broken_release_gets_the_dense_jacobian():
    assert constraint_jacobian("4.0.0") == mujoco.mjtJacobian.mjJAC_DENSE
    for version in ("3.17.0", "4.0.1", "4.1.0"):
        assert constraint_jacobian(version) == mujoco.mjtJacobian.mjJAC_AUTO
    assert constraint_jacobian() == constraint_jacobian(mujoco.__version__)


def test_a_world_compiles_with_the_release_s_jacobian(blocks):
    assert World([blocks["cube"]]).model.opt.jacobian == constraint_jacobian()
