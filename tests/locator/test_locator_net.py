"""The locator's network and weights file: shapes, a decision alone is the decision in a batch,
a saved locator loads and locates the same, bad input is named; and one simulated episode's
samples are labelled by the simulator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from mpg_agents.locator.cover import CoverRule
from mpg_agents.locator.features import QUERY_CHANNELS, SCENE_CHANNELS, Exemplar, net_inputs
from mpg_agents.locator.locator import TargetLocator, blob_weights, read_locator_header, save_locator, snap_to_blob
from mpg_agents.locator.net import LocatorConfig, LocatorNet
from mpg_agents.locator.run import write_locator
from mpg_envs.perception.exemplar_match import Blob, pose_table

SMALL = LocatorConfig(8, 8, 16)


def _obs(rng: np.random.Generator, size: int = 64) -> dict[str, np.ndarray]:
    return {
        "color": rng.integers(0, 256, (size, size, 3), dtype=np.uint8),
        "depth": rng.uniform(0, 0.1, (size, size)).astype(np.float32),
        "query_color": rng.integers(0, 256, (size, size, 3), dtype=np.uint8),
        "query_depth": rng.uniform(0, 0.05, (size, size)).astype(np.float32),
    }


def test_shapes_and_a_decision_alone_is_the_decision_in_a_batch():
    torch.manual_seed(0)
    net = LocatorNet(SMALL).eval()
    scene, query, descriptor = torch.rand(3, SCENE_CHANNELS, 64, 64), torch.rand(3, QUERY_CHANNELS, 64, 64), torch.rand(3, 6)
    with torch.no_grad():
        pixels, seen = net(scene, query, descriptor)
        alone, alone_seen = net(scene[1:2], query[1:2], descriptor[1:2])
    assert pixels.shape == (3, 64, 64) and seen.shape == (3,)
    assert torch.allclose(alone[0], pixels[1], atol=1e-5) and torch.allclose(alone_seen[0], seen[1], atol=1e-5)
    assert float(torch.sigmoid(pixels).mean()) < 0.1  # starts near "not the target"


def test_a_saved_locator_loads_and_locates_the_same(tmp_path: Path):
    torch.manual_seed(1)
    net = LocatorNet(SMALL)
    path = tmp_path / "locator.safetensors"
    rule = CoverRule(search="empty", area_share=0.6)
    save_locator(net, path, 0.5, 0.7, {"steps": 3}, rule, snap="shape")
    header = read_locator_header(path)
    assert header["seen_threshold"] == 0.7 and header["record"] == {"steps": 3} and header["config"] == SMALL.to_dict()
    loaded = TargetLocator.load(path)
    assert loaded.rule == rule and loaded.snap == "shape"  # the search rule and the snapping travel with the weights
    with pytest.raises(ValueError, match="snap must be one of"):
        TargetLocator(net, snap="yes")
    with pytest.raises(ValueError, match=r"pose_floor must lie in \[0, 1\]"):
        TargetLocator(net, snap="pose", pose_floor=1.5)
    save_locator(net, path, 0.5, 0.7, {}, snap="pose", pose_floor=0.25)
    assert TargetLocator.load(path).pose_floor == 0.25 and TargetLocator.load(path).snap == "pose"
    assert TargetLocator.load(path).grow == "rated"  # the default growth
    save_locator(net, path, 0.5, 0.7, {}, snap="template", min_fit=0.5, grow="fit")
    assert TargetLocator.load(path).grow == "fit" and TargetLocator.load(path).min_fit == 0.5
    save_locator(net, path, 0.5, 0.7, {"steps": 3})
    obs = _obs(np.random.default_rng(0))
    a, b = TargetLocator(net, 0.5, 0.7).locate(obs), TargetLocator.load(path).locate(obs)
    assert np.allclose(a.probability, b.probability, atol=1e-6) and a.seen == b.seen
    assert a.probability.shape == (64, 64) and a.mask.dtype == np.uint8
    if not a.seen:
        assert not a.mask.any()  # nothing is located where the target is not seen


def _boxes(colour: tuple[int, int, int]) -> dict[str, np.ndarray]:
    """A scene of three boxes (two of ``colour``) and an exemplar of one of them."""
    obs = _obs(np.random.default_rng(5))
    obs["color"][:], obs["depth"][:] = 90, 0.0
    obs["query_color"][:], obs["query_depth"][:] = 90, 0.0
    for rows, cols, paint in (
        (slice(5, 15), slice(5, 30), colour),
        (slice(30, 50), slice(30, 40), colour),
        (slice(40, 60), slice(2, 12), (225, 87, 89)),
    ):
        obs["color"][rows, cols], obs["depth"][rows, cols] = paint, 0.03
    obs["query_color"][20:30, 20:45], obs["query_depth"][20:30, 20:45] = colour, 0.03
    return obs


def test_what_is_read_of_an_exemplar_is_kept_while_it_stays_and_locating_is_the_same():
    torch.manual_seed(2)
    net = LocatorNet(SMALL).eval()
    green, orange = _boxes((89, 161, 79)), _boxes((242, 142, 43))
    exemplar = Exemplar.of(green)
    assert exemplar.shows(green) and not exemplar.shows(orange) and exemplar.model is not None
    kept = TargetLocator(net, 0.5, 0.0, snap="probability")
    for obs in (green, orange, green, green):  # the exemplar changes, comes back, stays
        fresh = TargetLocator(net, 0.5, 0.0, snap="probability").locate(obs)
        located = kept.locate(obs)
        with torch.no_grad():  # what every decision computed in full gives
            pixels, seen = net(*(torch.from_numpy(a)[None] for a in net_inputs(obs)))
        assert np.array_equal(located.probability, fresh.probability) and np.array_equal(located.mask, fresh.mask)
        assert np.array_equal(located.probability, torch.sigmoid(pixels[0]).numpy())
        assert located.seen_probability == fresh.seen_probability == float(torch.sigmoid(seen[0]))


def test_the_pose_snapping_weighs_uncovered_blobs_by_their_fit_and_rules_out_misfits():
    exemplar = Exemplar.of(_boxes((89, 161, 79)))  # a 10 x 25 pixel box, 3 cm high: 0.02 x 0.05 x 0.03 m
    assert exemplar.poses is not None and np.allclose(exemplar.poses, pose_table(exemplar.model[1]))

    def blob(rows: slice, cols: slice, height: float, covered: bool, score: float) -> Blob:
        pixels = np.zeros((64, 64), bool)
        pixels[rows, cols] = True
        return Blob(pixels, score, covered, height, height)

    fits = blob(slice(0, 10), slice(0, 25), 0.03, False, 0.9)  # the exemplar's box lying as it does
    too_low = blob(slice(20, 30), slice(0, 25), 0.01, False, 0.8)  # its footprint but 1 cm high: not it
    covered = blob(slice(40, 45), slice(0, 10), 0.03, True, 0.4)  # part of a top: judged by its score
    weights, ruled_out = blob_weights("pose", [fits, too_low, covered], exemplar, 0.1)
    assert weights is not None and ruled_out is not None
    assert weights[0] > 0.5 and weights[1] == 0.0 and weights[2] == 0.4
    assert np.array_equal(ruled_out, too_low.pixels)
    assert blob_weights("shape", [fits, too_low], exemplar, 0.1) == ([0.9, 0.8], None)
    assert blob_weights("probability", [fits, too_low], exemplar, 0.1) == (None, None)


class _Rates(LocatorNet):
    """A network that rates one region of the scene the target's (for the snapping's tests)."""

    def __init__(self, region: tuple[slice, slice]):
        super().__init__(SMALL)
        self.region = region

    def scene_logits(self, scene: torch.Tensor, embedding: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        pixels = torch.full(scene.shape[:1] + scene.shape[2:], -10.0)
        pixels[(slice(None), *self.region)] = 10.0
        return pixels, torch.full(scene.shape[:1], 10.0)


def test_a_locator_snapping_by_pose_does_not_see_the_target_where_only_misfits_rate_high():
    obs = _boxes((89, 161, 79))
    obs["depth"][30:50, 30:40] = 0.012  # the second box of the exemplar's colour: too low to be it
    first, second = (slice(5, 15), slice(5, 30)), (slice(30, 50), slice(30, 40))
    located = TargetLocator(_Rates(first), 0.5, 0.5, snap="pose").locate(obs)
    assert located.seen and located.mask[first].all() and located.mask.sum() == located.mask[first].size
    assert not TargetLocator(_Rates(second), 0.5, 0.5, snap="pose").locate(obs).seen
    assert TargetLocator(_Rates(second), 0.5, 0.5, snap="probability").locate(obs).seen  # without the pose check


class _RatesTwo(LocatorNet):
    """A network that rates two regions of the scene the target's, the second higher."""

    def __init__(self, first: tuple[slice, slice], second: tuple[slice, slice]):
        super().__init__(SMALL)
        self.first, self.second = first, second

    def scene_logits(self, scene: torch.Tensor, embedding: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        pixels = torch.full(scene.shape[:1] + scene.shape[2:], -10.0)
        pixels[(slice(None), *self.first)] = 0.5  # probability 0.62
        pixels[(slice(None), *self.second)] = 2.0  # probability 0.88
        return pixels, torch.full(scene.shape[:1], 10.0)


def test_the_template_snapping_takes_the_object_shaped_like_the_exemplar_over_a_look_alike_rated_higher():
    obs = _boxes((89, 161, 79))  # the exemplar: the first box (10 x 25)
    obs["color"][30:50, 40:60], obs["depth"][30:50, 40:60] = (89, 161, 79), 0.03  # the second, 20 x 30, shares its colour
    first, second = (slice(5, 15), slice(5, 30)), (slice(30, 50), slice(30, 60))
    net = _RatesTwo(first, second)
    located = TargetLocator(net, 0.5, 0.5, snap="template", min_fit=0.5).locate(obs)
    assert located.seen and located.fit is not None and located.fit > 0.9
    assert located.mask[first].all() and located.mask.sum() == located.mask[first].size
    by_probability = TargetLocator(net, 0.5, 0.5, snap="probability").locate(obs)
    assert by_probability.mask[second].all() and by_probability.fit is None  # the look-alike, without the fit
    # Only the look-alike rated: it is still taken (the target may rest in another pose), with its poor fit.
    alone = TargetLocator(_Rates(second), 0.5, 0.5, snap="template", min_fit=0.5).locate(obs)
    assert alone.seen and alone.mask[second].all() and alone.fit is not None and alone.fit < 0.5


def test_fit_growth_leaves_out_a_touching_object_of_the_same_colour_that_rated_growth_takes():
    obs = _boxes((89, 161, 79))  # the exemplar: the first box (10 x 25, 3 cm)
    obs["color"][15:25, 5:30], obs["depth"][15:25, 5:30] = (89, 161, 79), 0.05  # another shape of its colour, touching it
    first, both = (slice(5, 15), slice(5, 30)), (slice(5, 25), slice(5, 30))
    rated = TargetLocator(_Rates(both), 0.5, 0.5, snap="template", min_fit=0.5).locate(obs)
    assert rated.mask[both].all()  # grown over the whole object of the colour
    grown = TargetLocator(_Rates(both), 0.5, 0.5, snap="template", min_fit=0.5, grow="fit").locate(obs)
    assert grown.seen and grown.mask[first].all() and grown.mask.sum() == grown.mask[first].size and grown.fit > 0.9
    with pytest.raises(ValueError, match="grow must be one of"):
        TargetLocator(LocatorNet(SMALL), grow="all")


def test_the_template_snapping_falls_back_to_the_networks_pixels_where_no_blob_of_the_colour_shows():
    obs = _boxes((89, 161, 79))
    obs["color"][5:15, 5:30] = obs["color"][30:50, 30:40] = (225, 87, 89)  # nothing of the exemplar's colour left
    third = (slice(40, 60), slice(2, 12))
    located = TargetLocator(_Rates(third), 0.5, 0.5, snap="template", min_fit=0.5).locate(obs)
    assert located.seen and located.fit is None and located.mask[third].all() and located.mask.sum() == 200


def test_bad_input_is_named(tmp_path: Path):
    with pytest.raises(KeyError, match="query_color"):
        TargetLocator(LocatorNet(SMALL)).locate({"color": np.zeros((8, 8, 3)), "depth": np.zeros((8, 8))})
    with pytest.raises(FileNotFoundError, match="mpg-train-locator"):
        TargetLocator.load(tmp_path / "none.safetensors")
    other = tmp_path / "other.safetensors"
    from safetensors.torch import save_file

    save_file({"w": torch.zeros(1)}, str(other))
    with pytest.raises(ValueError, match="not a locator weights file"):
        read_locator_header(other)
    net = LocatorNet(SMALL)
    with torch.no_grad():
        net.seen_bias.fill_(float("nan"))
    with pytest.raises(ValueError, match="NaN"):
        save_locator(net, tmp_path / "nan.safetensors", 0.5, 0.5, {})


def test_one_episodes_samples_are_labelled_by_the_simulator():
    from mpg_agents.locator.samples import SOURCES, episode_samples, source_env

    source = next(s for s in SOURCES if s.name == "stage4")
    env = source_env(source, "blocks", 8)
    try:
        samples = episode_samples(env, source, 12)
    finally:
        env.close()
    assert 1 <= len(samples) <= source.motions + 1
    for sample in samples:
        label, visible = sample["label"], float(sample["visible_fraction"])
        assert label.shape == (224, 224) and set(np.unique(label)) <= {0, 1}
        assert (label.sum() > 0) == (visible > 0)
        assert np.all(sample["query_depth"][label > 0] >= 0) and sample["color"].dtype == np.uint8


def test_the_demo_shows_the_exemplar_and_the_locators_map():
    import gymnasium as gym

    from mpg_agents.demo import PANEL_PX, exemplar_panels, heightmap_panels

    env = gym.make("MPG-OccludedHardExemplar-v0")
    try:
        obs, _ = env.reset(seed=500052)
    finally:
        env.close()
    mask, panels = exemplar_panels(obs, TargetLocator(LocatorNet(SMALL)))
    assert mask.shape == obs["depth"].shape and len(panels) == 2
    assert all(panel.shape[1] == PANEL_PX for panel in panels)
    assert len(heightmap_panels(obs, mask)) == 2 and len(heightmap_panels(obs)) == 2  # no mask in exemplar mode: no outline


def test_the_mask_snaps_to_the_blob_the_network_favours():
    probability = np.zeros((6, 6), np.float32)
    probability[0:2, 0:2], probability[4:6, 4:6] = 0.9, 0.5
    a, b = np.zeros((6, 6), bool), np.zeros((6, 6), bool)
    a[0:3, 0:3], b[4:6, 3:6] = True, True  # means 4 x 0.9 / 9 = 0.4 and 4 x 0.5 / 6 = 0.33
    snapped = snap_to_blob(probability, [a, b], 0.3)
    assert snapped is not None and snapped.dtype == np.uint8 and np.array_equal(snapped, a)
    probability[4:6, 3:6] = 0.6  # b's mean is now 0.6
    assert np.array_equal(snap_to_blob(probability, [a, b], 0.5), b)
    assert snap_to_blob(probability, [a, b], 0.7) is None and snap_to_blob(probability, [], 0.1) is None
    # Weighed by the matcher's shape scores, a's 0.4 x 0.9 = 0.36 beats b's 0.6 x 0.5 = 0.3.
    assert np.array_equal(snap_to_blob(probability, [a, b], 0.3, [0.9, 0.5]), a)
    assert snap_to_blob(probability, [a, b], 0.3, [0.0, 0.0]) is None  # no blob has the shape


def test_a_locator_is_written_with_its_model_card_beside_it(tmp_path: Path):
    record = {
        "parameters": 1,
        "command": "mpg-train-locator --out x",
        "train_samples": 1,
        "train_shards": 1,
        "seed": 1,
        "steps": 1,
        "batch_size": 1,
        "learning_rate": 0.001,
        "train_seconds": 1.0,
        "machine": "2 CPU cores",
        "collect_seconds": 1.0,
        "threshold": 0.5,
        "seen_threshold": 0.7,
        "tuning_samples": 1,
        "tuning_figures": {"hidden": {"samples": 1, "seen_rate": 0.0}},
    }
    card = write_locator(TargetLocator(LocatorNet(SMALL), 0.5, 0.7, record), tmp_path / "locator.safetensors")
    assert card == tmp_path / "locator.md" and "mpg-train-locator --out x" in card.read_text()
    assert TargetLocator.load(tmp_path / "locator.safetensors").record == record
    hidden = {"false_claim_rate": 0.1, "interval_95": [0.03, 0.3], "hidden_states": 20.0, "false_claims": 2.0}
    record["heldout_hidden"] = {"seed": 500000, "cells": {"MPG-OccludedHardExemplar-v0 30": hidden}}
    card = write_locator(TargetLocator(LocatorNet(SMALL), 0.5, 0.7, record), tmp_path / "locator.safetensors")
    assert "| MPG-OccludedHardExemplar-v0 30 | 20 | 2 | 10.0% [3.0%, 30.0%] |" in card.read_text()
