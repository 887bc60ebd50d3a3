"""Arranged scenes: hand-checked placements, seeded draws that stay in the workspace, stacking,
and the settle check."""

from __future__ import annotations

import json
import math

import gymnasium as gym
import numpy as np
import pytest

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_envs.grid.workspace import Workspace
from mpg_envs.scenes.arranged import (
    ARRANGEMENT_KINDS,
    ArrangedScenes,
    Arrangement,
    ArrangementError,
    Block,
    arrangement_scene,
    half_extents,
    settle_arrangement,
)
from mpg_envs.scenes.arrangement_draw import draw_arrangement
from mpg_envs.scenes.cases import load_cases

WS = Workspace()
ARRANGEMENT_SHAPES = ("cube", "long_box", "flat_box", "tall_box", "cylinder", "disc", "triangular_prism", "arch")


def footprint_corners(block: Block) -> np.ndarray:
    hx, hy = half_extents(block.shape)
    c, s = math.cos(math.radians(block.yaw)), math.sin(math.radians(block.yaw))
    local = np.array([[hx, hy], [hx, -hy], [-hx, hy], [-hx, -hy]])
    return local @ np.array([[c, s], [-s, c]]) + [block.x, block.y]


def test_half_extents_are_the_blocks_sets():
    # The blocks set of seed 0: the cube is 51.4 mm, the tall box 43.2 x 42.9 x 86.8 mm.
    assert half_extents("cube") == pytest.approx((25.7, 25.7), abs=0.05)
    assert half_extents("tall_box") == pytest.approx((21.6, 21.45), abs=0.05)
    with pytest.raises(ValueError, match="unknown block shape 'sphere'.*valid"):
        half_extents("sphere")


def test_boxed_in_blocks_stand_clear_and_the_first_neighbour_its_gap_away():
    """In the arrangement's own (unturned) frame every two blocks' footprints are at least
    1 mm apart, and the first neighbour, placed when only the target stood, is 1-3 mm from it
    (a later one is pushed out when a wider neighbour is in its way)."""
    for seed in range(20):
        a = draw_arrangement(seed, kind="boxed-in", loose=(0, 0))
        target = a.blocks[0]
        turn = math.radians(target.yaw)  # the target stands at local yaw 0
        rot = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
        rects = []
        for b in a.blocks:
            x, y = rot.T @ np.array([b.x - target.x, b.y - target.y])
            quarter = round(((b.yaw - target.yaw) % 180) / 90) % 2
            rects.append((x, y, *half_extents(b.shape)[:: -1 if quarter else 1]))
        gaps = {
            (i, j): max(abs(p[0] - q[0]) - p[2] - q[2], abs(p[1] - q[1]) - p[3] - q[3])
            for i, p in enumerate(rects) for j, q in enumerate(rects) if i < j
        }  # fmt: skip
        assert min(gaps.values()) >= 1.0 - 1e-6, (seed, gaps)
        assert 1.0 - 1e-6 <= gaps[(0, 1)] <= 3.0 + 1e-6, (seed, gaps[(0, 1)])


def test_draws_are_seeded_and_stay_in_the_workspace():
    half = 500 * (WS.x_max - WS.x_min)
    kinds = set()
    for seed in range(700000, 700150):
        a = draw_arrangement(seed)
        assert a == draw_arrangement(seed)
        kinds.add(a.name.rsplit("-", 1)[0])
        corners = np.concatenate([footprint_corners(b) for b in a.blocks])
        assert np.all(np.abs(corners) <= half + 1e-6), a.name
        assert a.target == 0 and a.visible[0] <= a.visible[1]
    assert kinds == set(ARRANGEMENT_KINDS)
    assert draw_arrangement(1) != draw_arrangement(2)


@pytest.mark.parametrize("kind", ["edge", "corner"])
def test_edge_kinds_put_the_target_4_to_12_mm_from_the_edge(kind):
    half = 500 * (WS.x_max - WS.x_min)
    for seed in range(30):
        target = draw_arrangement(seed, kind=kind).blocks[0]
        margins = half - np.abs(footprint_corners(target)).max(axis=0)  # per axis, mm
        near = margins[margins < 20]
        assert len(near) == (1 if kind == "edge" else 2), (seed, margins)
        assert np.all((near >= 4 - 1e-6) & (near <= 12 + 1e-6)), (seed, margins)


def test_bad_draw_arguments_name_what_is_valid():
    with pytest.raises(ValueError, match="unknown arrangement kind 'pile'.*boxed-in"):
        draw_arrangement(0, kind="pile")
    with pytest.raises(ValueError, match="seed"):
        draw_arrangement(-1)
    with pytest.raises(ValueError, match="loose"):
        draw_arrangement(0, loose=(3, 1))


def test_stacked_blocks_start_just_above_what_is_under_them():
    # A flat box (28.6 mm tall) on a cube (51.4 mm, itself 0.5 mm up): its centre
    # 0.5 + 51.4 + 0.5 + 14.3 mm up.
    a = Arrangement("stack", "", 0, (Block("cube", 0, 0), Block("flat_box", 0, 0, 90), Block("disc", 120, 0)))
    scene = arrangement_scene(a)
    z = [obj.position[2] for obj in scene.objects]
    assert z[0] == pytest.approx(0.0257 + 0.0005, abs=1e-4)
    assert z[1] == pytest.approx(0.0005 + 0.0514 + 0.0005 + 0.0143, abs=1e-4)
    assert z[2] == pytest.approx(0.0142 + 0.0005, abs=1e-4)  # beside, on the table
    assert scene.objects[0].position[:2] == pytest.approx(WS.center[:2])
    with pytest.raises(ValueError, match="block 0: unknown shape 'ball'"):
        arrangement_scene(Arrangement("bad", "", 0, (Block("ball", 0, 0),)))


def test_settling_keeps_a_drawn_arrangement_and_refuses_a_wrong_band():
    env = gym.make("MPG-Occluded-v0").unwrapped
    try:
        a = draw_arrangement(700011, kind="ring")
        scene, visible = settle_arrangement(env, a)
        assert a.visible[0] <= visible <= a.visible[1] and len(scene.objects) == len(a.blocks)
        hidden = Arrangement("hidden?", "", 0, a.blocks, visible=(0.0, 0.5))
        with pytest.raises(ArrangementError, match=r"visible, outside the band \[0, 0.5\]"):
            settle_arrangement(env, hidden)
        toppling = Arrangement("topple", "", 0, (Block("disc", 0, 0), Block("tall_box", 40, 0, 0, side=True)))
        with pytest.raises(ArrangementError, match="moved"):
            settle_arrangement(env, toppling)
    finally:
        env.close()


def test_make_arranged_writes_a_case_folder(benchmark_script, tmp_path):
    script = benchmark_script("make_arranged")
    record = script.make_set(700000, 3, tmp_path)
    assert [k["seed"] for k in record["kept"]] == [700000, 700001, 700002] and not record["skipped"]
    cases = load_cases(tmp_path)
    assert [c.name for c in cases] == [k["name"] for k in record["kept"]]
    assert all(c.note for c in cases)
    assert json.loads((tmp_path / "arranged.json").read_text())["seeds_tried"] == 3


# ------------------------------------------------------------------------------ env option
def test_the_arranged_option_reads_a_share_or_a_table_and_names_what_is_wrong():
    assert ArrangedScenes.from_option(None) is None and ArrangedScenes.from_option(0) is None
    assert ArrangedScenes.from_option(0.25) == ArrangedScenes(0.25)
    assert ArrangedScenes.from_option({"share": 1, "kinds": ["ring"]}).kinds == ("ring",)
    for bad, match in ((1.5, "share"), (True, "arranged must be"), ({"share": 0.5, "kinds": ["pile"]}, "kinds"),
                       ({"kinds": ["ring"]}, "share \\(required\\)"), ({"share": 0.5, "tries": 0}, "tries"), ("ring", "arranged must be")):  # fmt: skip
        with pytest.raises(ValueError, match=match):
            ArrangedScenes.from_option(bad)
    with pytest.raises(ValueError, match="arranged share"):
        gym.make("MPG-Stage4-v0", arranged=2.0)


def test_arranged_resets_start_as_designed_and_leave_other_resets_alone():
    plain = gym.make("MPG-Stage4-v0")
    arranged = gym.make("MPG-Stage4-v0", arranged={"share": 1.0, "kinds": ["ring", "boxed-in"]})
    try:
        a, info = arranged.reset(seed=3)
        b, _ = arranged.reset(seed=3)
        assert all(np.array_equal(a[k], b[k]) for k in a)  # seeded
        scene = arranged.unwrapped.current_scene()
        assert {obj.asset.name for obj in scene.objects} <= set(ARRANGEMENT_SHAPES)  # the blocks, placed
        assert info["visible_fraction"] >= 0.9 and not info["occluded"]  # the kinds' band, not Stage IV's rule
        # With the option off, the episode is the plain env's, draw for draw.
        off = gym.make("MPG-Stage4-v0", arranged=None)
        c, _ = off.reset(seed=3)
        d, _ = plain.reset(seed=3)
        assert all(np.array_equal(c[k], d[k]) for k in c)
        off.close()
        # A test seed still loads its shipped scene.
        occluded = gym.make("MPG-Occluded-v0", arranged=1.0)
        e, _ = occluded.reset(seed=500000)
        f, _ = gym.make("MPG-Occluded-v0").reset(seed=500000)
        assert all(np.array_equal(e[k], f[k]) for k in e)
        occluded.close()
    finally:
        plain.close()
        arranged.close()


def test_a_stage_may_train_on_arranged_scenes():
    import dataclasses

    from mpg_agents.learning.training_stages import TRAINING_STAGES

    stage = next(s for s in TRAINING_STAGES if s.name == "Stage4")
    ok = dataclasses.replace(stage, env_options={"arranged": {"share": 0.3, "kinds": ["ring"]}})
    assert dict(ok.env_options)["arranged"] == {"share": 0.3, "kinds": ["ring"]}
    with pytest.raises(ValueError, match="arranged share"):
        dataclasses.replace(stage, env_options={"arranged": 3})
