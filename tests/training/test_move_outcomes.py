"""The pixel classes and summary of mpg_agents.evaluation.move_outcomes on hand-checked cases."""

import pytest

from mpg_agents.evaluation import move_outcomes as bench


def test_a_pixel_is_table_target_occluder_or_other():
    assert bench.classify_pixel(-1, target=3, occluders=[5]) == "table"
    assert bench.classify_pixel(3, target=3, occluders=[5]) == "target"
    assert bench.classify_pixel(5, target=3, occluders=[5, 7]) == "occluder"
    assert bench.classify_pixel(6, target=3, occluders=[5, 7]) == "other"


def test_summary_counts_moves_by_spot_and_angle():
    rec = lambda on, angle, lifted, any_angle, oracle: {  # noqa: E731
        "on": on, "angle_off_deg": angle, "lifted": lifted, "any_angle_lifts": any_angle, "oracle_lifts": oracle}
    records = [rec("table", None, False, False, True), rec("occluder", 10.0, True, True, True),
               rec("occluder", 60.0, False, True, False), rec("occluder", 25.0, False, False, None),
               rec("target", 5.0, False, False, True)]
    out = bench.summarise_moves(records)
    assert (out["moves"], out["lifted"]) == (5, 1)
    assert out["on"] == {"table": 1, "target": 1, "occluder": 3, "other": 0}
    assert out["lifted_on"] == {"table": 0, "target": 0, "occluder": 1, "other": 0}
    # 25 degrees counts as on the axis (the limit is inclusive)
    assert (out["occluder_on_axis"], out["occluder_on_axis_lifted"]) == (2, 1)
    assert (out["occluder_off_axis"], out["occluder_off_axis_lifted"]) == (1, 0)
    assert out["any_angle_lifts"] == 2
    assert (out["oracle_tried"], out["oracle_lifts"]) == (4, 3)
    with pytest.raises(ValueError, match="no moves"):
        bench.summarise_moves([])
