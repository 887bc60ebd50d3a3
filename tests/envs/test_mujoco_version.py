"""The MuJoCo release a world runs on: MuJoCo 4.0.0's sparse solver is avoided, every other
release keeps MuJoCo's own choice (so 3.x results stay bit for bit)."""

import dataclasses

import mujoco
import pytest

from mpg_envs.scenes.test_sets import (
    ACROSS_MUJOCO_TOLERANCE,
    VISIBLE_FRACTION_TOLERANCE,
    ChangedTestSetError,
    find_test_set,
)
from mpg_envs.simulation.mujoco_version import constraint_jacobian
from mpg_envs.simulation.world import World


def test_only_the_broken_release_gets_the_dense_jacobian():
    assert constraint_jacobian("4.0.0") == mujoco.mjtJacobian.mjJAC_DENSE
    for version in ("3.17.0", "4.0.1", "4.1.0"):
        assert constraint_jacobian(version) == mujoco.mjtJacobian.mjJAC_AUTO
    assert constraint_jacobian() == constraint_jacobian(mujoco.__version__)


def test_a_world_compiles_with_the_release_s_jacobian(blocks):
    assert World([blocks["cube"]]).model.opt.jacobian == constraint_jacobian()


def test_a_test_set_of_another_major_version_is_checked_to_its_ray_casts():
    """A set made on another MuJoCo major version is placed bit for bit, but its ray casts hit a
    few pixels at mesh edges otherwise: checked to ACROSS_MUJOCO_TOLERANCE, both versions named."""
    made = find_test_set("occluded_hard", 15)
    here = dataclasses.replace(made, meta={**made.meta, "mujoco_version": mujoco.__version__})
    major = int(mujoco.__version__.split(".")[0])
    other = dataclasses.replace(made, meta={**made.meta, "mujoco_version": f"{7 - major}.0.0"})
    assert here.visible_fraction_tolerance() == VISIBLE_FRACTION_TOLERANCE
    assert other.visible_fraction_tolerance() == ACROSS_MUJOCO_TOLERANCE == 0.02
    recorded = float(made.visible_fraction[0])
    other.check_visible_fraction(500000, recorded + 0.011)  # MuJoCo 4's largest difference on 3.17's sets
    with pytest.raises(ChangedTestSetError, match=rf"tolerance 0.0001\); .*made with MuJoCo {mujoco.__version__}, this is"):
        here.check_visible_fraction(500000, recorded + 0.011)
    with pytest.raises(ChangedTestSetError, match=rf"tolerance 0.02\); .*made with MuJoCo {7 - major}.0.0, this is MuJoCo {mujoco.__version__}\)$"):
        other.check_visible_fraction(500000, recorded + 0.03)
    legacy = dataclasses.replace(made, meta={k: v for k, v in made.meta.items() if k != "mujoco_version"})
    assert legacy.made_with_mujoco == "3.x"
