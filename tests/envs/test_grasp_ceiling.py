"""The physical ceiling, on a few placements: every block can be grasped alone at its centre
across its short axis (benchmarks/grasp_ceiling.py runs 100 placements per shape)."""

from __future__ import annotations

import pytest

from mpg_envs.simulation.objects import blocks_object_set
from mpg_envs.simulation.robot import ArmIK



@pytest.fixture(scope="module")
def ceiling():
    import mpg_envs.tasks.grasp_ceiling

    return mpg_envs.tasks.grasp_ceiling


@pytest.fixture(scope="module")
def ik() -> ArmIK:
    return ArmIK()


@pytest.mark.parametrize("shape", [a.name for a in blocks_object_set()])
def test_every_shape_is_grasped_alone(ceiling, ik, shape) -> None:
    asset = {a.name: a for a in blocks_object_set()}[shape]
    result = ceiling.run_shape(asset, placements=3, seed=7, ik=ik)
    assert result.trials == 3
    assert result.successes == 3, f"{shape}: failures {dict(result.failures)}"


def test_a_grasp_beside_the_object_fails_as_closed_empty(ceiling, ik) -> None:
    """The failure kinds are real: fingers closing 6 cm off the cube close on nothing."""
    import numpy as np

    from mpg_envs.grid.workspace import world_to_pixel

    bench = ceiling.GraspBench(blocks_object_set()[0], ik=ik)
    try:
        bench.world.drop_object(0, (0.5, 0.0), (1.0, 0.0, 0.0, 0.0))
        depth = bench.heightmapper(bench.world.data).depth
        row, col = world_to_pixel(bench.world.workspace, 0.5, 0.06)
        result = bench.executor.execute("grasp", 0, row, col, np.asarray(depth), target=0)
    finally:
        bench.close()
    assert not result.lifted
    assert result.grasp_failure == "closed_empty"


def test_unknown_drop_mode_is_refused(ceiling, ik) -> None:
    import numpy as np

    bench = ceiling.GraspBench(blocks_object_set()[0], ik=ik)
    try:
        with pytest.raises(ValueError, match="drop must be one of"):
            bench.trial(np.random.default_rng(0), drop="sideways")
    finally:
        bench.close()
