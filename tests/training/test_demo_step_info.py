"""Each step's info as fixed columns (mpg_agents.demos.step_info): hand-checked encodings."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from mpg_agents.demos.step_info import FIELD_NAMES, INFO_FIELDS, OTHER, decode_infos, encode_infos

RESET = {
    "num_motions": 0,
    "occluded": True,
    "visible_fraction": 0.25,
    "objects_left": 15,
    "target": 3,
    "is_success": False,
}
STEP = {
    "primitive": "grasp",
    "rotation": 5,
    "pixel": (120, 64),
    "position": (0.5, -0.1, 0.02),
    "grasp_failure": None,
    "unreachable": False,
    "physics_steps": 545,
    "lifted": True,
    "grasp_success": True,
    "target_grasped": False,
    "wrong_grasp": True,
    "change_detected": True,
    "occluded_before": True,
    "occluded": False,
    "visible_fraction": None,
    "move_success": False,
    "is_success": False,
    "objects_left": 14,
    "target_out_of_workspace": False,
    "grasp_q_gain": 0.0,
    "visible_gain": 0.5,
    "num_motions": 1,
    "sim_warnings": {"contacts": np.int64(2)},
    "end_reason": None,
}


def test_columns_hold_every_field_with_missing_values_filled():
    columns = encode_infos([RESET, STEP])
    assert tuple(columns) == FIELD_NAMES
    assert columns["primitive"] == ["", "grasp"]  # the reset made no motion
    assert columns["rotation"] == [-1, 5]
    assert columns["pixel"].dtype == np.int64 and columns["pixel"].tolist() == [[-1, -1], [120, 64]]
    assert columns["position"].shape == (2, 3) and np.isnan(columns["position"][0]).all()
    assert columns["position"][1].tolist() == [0.5, -0.1, 0.02]
    assert columns["grasp_failure"] == ["", ""]  # None: no failure
    assert columns["wrong_grasp"] == [False, True] and columns["lifted"] == [False, True]
    assert columns["visible_fraction"][0] == 0.25 and math.isnan(columns["visible_fraction"][1])  # None -> NaN
    assert columns["objects_left"] == [15, 14]
    assert columns["target"] == [3, -1]  # reported at the reset only
    assert columns["end_reason"] == ["", ""]
    assert columns["num_motions"] == [0, 1]
    # Keys outside the fixed fields keep their values, as JSON.
    assert [json.loads(t) for t in columns[OTHER]] == [{}, {"sim_warnings": {"contacts": 2}}]


def test_decoding_gives_the_steps_back():
    rows = decode_infos(encode_infos([RESET, STEP]))
    assert rows[0]["primitive"] is None and rows[0]["target"] == 3 and rows[0]["visible_fraction"] == 0.25
    assert rows[0]["pixel"] is None and rows[0]["position"] is None
    step = rows[1]
    for key, value in STEP.items():
        if key == "sim_warnings":
            assert step[key] == {"contacts": 2}
        elif isinstance(value, tuple):
            assert step[key] == pytest.approx(value)
        else:
            assert step[key] == value, key
    assert step["target"] is None


def test_decoding_reads_text_as_bytes_as_hdf5_returns_it():
    columns = encode_infos([RESET, dict(STEP, end_reason="wrong_object", grasp_failure="not_lifted")])
    as_hdf5 = {
        k: (np.array([s.encode() for s in v], dtype=object) if isinstance(v, list) and isinstance(v[0], str) else v)
        for k, v in columns.items()
    }
    rows = decode_infos(as_hdf5)
    assert (
        rows[1]["end_reason"] == "wrong_object"
        and rows[1]["grasp_failure"] == "not_lifted"
        and rows[1]["primitive"] == "grasp"
    )


def test_every_step_has_the_same_structure():
    columns = encode_infos([RESET, STEP, dict(STEP, end_reason="target_grasped", is_success=True)])
    assert {len(v) for v in columns.values()} == {3}
    assert columns["end_reason"] == ["", "", "target_grasped"]


@pytest.mark.parametrize(
    ("key", "value", "says"),
    [
        ("rotation", "five", "must be a number"),
        ("rotation", 2.5, "must be a whole number"),
        ("lifted", 1, "must be a bool"),
        ("primitive", 3, "must be a string"),
        ("pixel", (1, 2, 3), "must hold 2 numbers"),
        ("visible_fraction", True, "must be a number"),
    ],
)
def test_a_value_of_the_wrong_type_is_named(key, value, says):
    with pytest.raises(ValueError, match=rf"info\['{key}'\] of step 1 {says}"):
        encode_infos([RESET, dict(STEP, **{key: value})])


def test_an_extra_value_json_cannot_hold_is_named():
    with pytest.raises(ValueError, match=r"info\['handle'\] holds a object"):
        encode_infos([dict(RESET, handle=object())])


def test_no_infos_and_missing_columns_are_refused():
    with pytest.raises(ValueError, match="at least its reset's info"):
        encode_infos([])
    columns = encode_infos([RESET])
    del columns["end_reason"]
    with pytest.raises(ValueError, match="lack the columns \\['end_reason'\\]"):
        decode_infos(columns)


def test_the_fields_are_named_once():
    names = [f.name for f in INFO_FIELDS]
    assert len(set(names)) == len(names) and OTHER not in names
