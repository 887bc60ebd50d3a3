"""The locator's pure parts by hand: inputs, figures, the loss, the learning-rate schedule,
the seen threshold's calibration and the sample plan's seeds."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from mpg_agents.locator.features import (
    DEPTH_SCALE,
    LAB_SCALE,
    SCENE_CHANNELS,
    colour_distance,
    match_cues,
    query_descriptor,
    query_input,
    scene_input,
)
from mpg_agents.locator.metrics import band_name, in_band, iou, locator_figures
from mpg_agents.locator.run import calibrate_seen, model_card
from mpg_agents.locator.samples import TUNING_SEEDS, disturbing_action, shard_plan
from mpg_agents.locator.training import learning_rate_factor, locator_loss, symmetry
from mpg_envs.grid.actions import decode_action


def _query(size: int = 8) -> tuple[np.ndarray, np.ndarray]:
    color = np.zeros((size, size, 3), np.uint8)
    depth = np.zeros((size, size), np.float32)
    color[2:4, 2:6] = (255, 0, 0)  # 8 red pixels, 4 of them 5 cm tall, 4 of them 3 cm
    depth[2:3, 2:6], depth[3:4, 2:6] = 0.05, 0.03
    return color, depth


def test_the_query_descriptor_by_hand():
    area, top, mean, r, g, b = query_descriptor(*_query())
    assert area == pytest.approx(8 / 64) and top == pytest.approx(0.5) and mean == pytest.approx(0.4)
    assert (r, g, b) == pytest.approx((1.0, 0.0, 0.0))
    assert not query_descriptor(np.zeros((4, 4, 3), np.uint8), np.zeros((4, 4), np.float32)).any()


def test_colour_distance_and_the_input_channels_by_hand():
    color = np.array([[[255, 0, 0], [0, 0, 0]], [[255, 255, 255], [0, 255, 0]]], np.uint8)
    distance = colour_distance(color, np.array([1.0, 0.0, 0.0]))
    assert distance == pytest.approx(np.array([[0.0, 1.0], [math.sqrt(2), math.sqrt(2)]]), abs=1e-6)
    query_color, query_depth = _query(2)
    obs = {"color": color, "depth": np.full((2, 2), 0.02, np.float32), "query_color": query_color, "query_depth": query_depth}
    scene = scene_input(obs)
    assert scene.shape == (SCENE_CHANNELS, 2, 2) and scene[3] == pytest.approx(np.full((2, 2), 0.02 * DEPTH_SCALE))
    assert scene[0, 0, 0] == 1.0 and scene[4, 0, 0] == pytest.approx(1.0)  # the empty query's colour is black
    assert query_input(obs).shape == (4, 2, 2)
    assert scene[5] == pytest.approx(np.ones((2, 2))) and not scene[6:].any()  # an empty query: nothing matches


def test_the_matchers_cues_by_hand():
    """A 4 x 4 red block 2 cm tall is asked for; the scene holds it, a red 8 x 2 block as tall
    with a grey wall along one long side, and a blue 4 x 4 block (2 mm pixels)."""
    red, blue, grey = (255, 0, 0), (0, 0, 255), (128, 128, 128)
    query_color, query_depth = np.zeros((24, 24, 3), np.uint8), np.zeros((24, 24), np.float32)
    query_color[10:14, 10:14], query_depth[10:14, 10:14] = red, 0.02
    color, depth = np.zeros((24, 24, 3), np.uint8), np.zeros((24, 24), np.float32)
    color[2:6, 2:6], depth[2:6, 2:6] = red, 0.02  # the target
    color[12:20, 4:6], depth[12:20, 4:6] = red, 0.02  # same colour, another shape
    color[12:20, 6:9], depth[12:20, 6:9] = grey, 0.05  # higher, along its rim: it is covered
    color[2:6, 16:20], depth[2:6, 16:20] = blue, 0.02  # same shape, another colour
    cues = match_cues({"color": color, "depth": depth, "query_color": query_color, "query_depth": query_depth})
    assert cues[0][2:6, 2:6] == pytest.approx(np.zeros((4, 4)), abs=1e-6)
    assert cues[0, 3, 17] > 100 / LAB_SCALE  # blue is far from red in CIELAB
    # The target: height 2 cm is the query's, its 8 x 8 mm footprint fits and shows whole: score 1.
    assert cues[1][2:6, 2:6] == pytest.approx(np.ones((4, 4)), abs=1e-3) and not cues[2][2:6, 2:6].any()
    # The 16 x 4 mm blob, covered (so its footprint is not asked to show whole): the long side
    # is 8 mm over the query's, one extent tolerance (8 mm): exp(-1/2).
    assert cues[1][12:20, 4:6] == pytest.approx(np.full((8, 2), math.exp(-0.5)), abs=1e-3)
    assert cues[2][12:20, 4:6].all() and not cues[1:, 2:6, 16:20].any() and not cues[1:, 12:20, 6:9].any()


def test_iou_and_the_bands_by_hand():
    a = np.zeros((4, 4), bool)
    b = np.zeros((4, 4), bool)
    a[0, :2], b[0, 1:3] = True, True
    assert iou(a, b) == pytest.approx(1 / 3) and iou(b * 0, a * 0) == 1.0 and iou(a, b * 0) == 0.0
    assert in_band(0.0, (0.0, 0.0)) and not in_band(0.01, (0.0, 0.0)) and in_band(0.3, (0.1, 0.3))
    assert not in_band(0.1, (0.1, 0.3)) and band_name((0.0, 0.0)) == "hidden" and band_name((0.6, 1.01)) == "60-100%"
    figures = locator_figures([a, a, b * 0], [True, True, True], [b, a, b * 0], [0.5, 0.7, 0.0])
    assert figures["hidden"] == {"samples": 1.0, "seen_rate": 1.0}  # a false claim
    assert figures["at least 30%"]["iou"] == pytest.approx((1 / 3 + 1) / 2)


def test_the_loss_by_hand():
    labels = torch.zeros(1, 2, 2)
    labels[0, 0, 0] = 1
    logits = torch.zeros(1, 2, 2)
    total, parts = locator_loss(logits, torch.zeros(1), labels)
    # BCE at p = 0.5 is ln 2 per pixel; the target pixel weighs 4: (4 + 3) ln 2 / 4 pixels.
    assert parts["pixel"] == pytest.approx(7 * math.log(2) / 4, rel=1e-5)
    assert parts["dice"] == 0.0  # one target pixel: below the 10 that count as seen, no Dice term
    assert parts["seen"] == pytest.approx(math.log(2), rel=1e-5)  # "not seen" at p = 0.5
    assert float(total) == pytest.approx(parts["pixel"] + parts["seen"], rel=1e-5)


def test_the_learning_rate_warms_up_then_decays_to_zero():
    assert learning_rate_factor(0, 100) == pytest.approx(0.2)  # 5 warm-up steps
    assert learning_rate_factor(5, 100) == pytest.approx(1.0)
    assert learning_rate_factor(100, 100) == pytest.approx(0.0, abs=1e-9)


def test_a_symmetry_turns_and_mirrors():
    a = np.arange(4).reshape(2, 2)
    assert symmetry(a, 1, False).tolist() == [[1, 3], [0, 2]]
    assert symmetry(a, 0, True).tolist() == [[1, 0], [3, 2]]


def test_the_seen_threshold_claims_at_most_the_allowed_share_of_hidden_targets():
    hidden = [0.1 * k for k in range(10)]  # 0.0 .. 0.9
    seen = hidden + [0.95]
    visible = [0.0] * 10 + [0.5]
    threshold = calibrate_seen(seen, visible, false_claims=0.1)  # one of ten may be claimed
    assert 0.8 < threshold <= 0.9 + 1e-5 and sum(s >= threshold for s in hidden) == 1
    assert calibrate_seen([0.2], [0.0], false_claims=0.0) == 0.5  # never below 0.5
    assert calibrate_seen([0.9], [0.4]) == 0.5  # no hidden sample


def test_sample_seeds_are_the_runs_own_or_the_tuning_seeds():
    plan = shard_plan(10, 3, 1)
    seeds = [s for _, _, shard in plan for s in shard]
    assert len(set(seeds)) == 30 and min(seeds) == 1_000_003
    tuning = [s for _, _, shard in shard_plan(4, 2, 1, tuning=True) for s in shard]
    assert tuning == list(range(TUNING_SEEDS.start, TUNING_SEEDS.start + 8))
    assert [s for _, _, shard in shard_plan(2, 2, 0) for s in shard] == [0, 1, 2, 3]
    with pytest.raises(ValueError, match="meet the test and tuning seeds"):
        shard_plan(10, 60000, 0)


def test_a_disturbing_action_is_a_move_or_push_at_an_object():
    depth = np.zeros((224, 224), np.float32)
    depth[100:110, 50:60] = 0.05
    rng = np.random.default_rng(0)
    for _ in range(20):
        action = decode_action(("move", "push", "grasp"), disturbing_action(("move", "push", "grasp"), depth, depth > 0, rng))
        assert action.primitive in ("move", "push") and 100 <= action.row < 110 and 50 <= action.col < 60
    only_push = decode_action(("push", "grasp"), disturbing_action(("push", "grasp"), depth, depth > 0, rng))
    assert only_push.primitive == "push"


def test_a_photo_of_the_object_is_centred_as_the_envs_show_the_exemplar():
    from mpg_agents.locator.features import centred_query

    color = np.zeros((10, 10, 3), np.uint8)
    depth = np.zeros((10, 10), np.float32)
    depth[0:2, 7:10], color[0:2, 7:10] = 0.04, 200  # rows 0-1, cols 7-9: middle at (1, 8)
    query_color, query_depth = centred_query(color, depth)
    rows, cols = np.nonzero(query_depth > 0)
    assert (rows.min(), rows.max(), cols.min(), cols.max()) == (4, 5, 4, 6)
    assert query_color[4, 4].tolist() == [200, 200, 200] and query_depth.dtype == np.float32
    with pytest.raises(ValueError, match="no pixel of the object's heightmap"):
        centred_query(color, np.zeros((10, 10), np.float32))


def test_the_model_card_names_the_rule_and_the_heldout_figures():
    band = {"30-60%": {"samples": 4, "iou": 0.85, "seen_rate": 1.0}, "hidden": {"samples": 2, "seen_rate": 0.0}}
    record = {
        "parameters": 10,
        "command": "mpg-train-locator --out x",
        "train_samples": 5,
        "train_shards": 1,
        "seed": 1,
        "steps": 2,
        "batch_size": 2,
        "learning_rate": 0.001,
        "train_seconds": 60.0,
        "machine": "2 CPU cores",
        "collect_seconds": 120.0,
        "threshold": 0.5,
        "seen_threshold": 0.9,
        "tuning_samples": 6,
        "tuning_figures": band,
    }
    plain = model_card(record)
    assert "| 30-60% | 4 | 0.850 | 100.0% |" in plain and "Cover and search rule" not in plain
    record["rule_tuning"] = {"env": "E", "objects": [15], "episodes": 3, "seed": 700000, "rules": [{}, {}]}
    record["heldout"] = {"seed": 500000, "episodes": 2, "cells": ["E 15"], "motions": 4, "median_decision_s": 0.012, "pooled": band}
    card = model_card(record, {"search": "empty"}, "probability")
    assert '`{"search": "empty"}`' in card and "among\n2 candidates on 3 tuning episodes" in card
    assert "masks snapping\n`probability`" in card
    assert "seeds 500000 on" in card and "12.0 ms per decision" in card and "| hidden | 2 | - | 0.0% (false claims) |" in card
