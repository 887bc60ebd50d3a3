"""Q-map PNG: one titled panel per primitive on one colour scale, the chosen action drawn and named."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from mpg_agents.evaluation.visualize import (
    COLORBAR_PX,
    FOOTER_PX,
    HEADER_PX,
    action_label,
    save_policy_qmaps,
    save_qmap_png,
)
from mpg_envs.grid.actions import PRIMITIVES, PixelAction, PixelActionSpace, encode_action
from mpg_envs.tasks.env import observation_space

from .fake_env import random_scene


def test_action_label_names_primitive_angle_pixel_and_q():
    assert action_label(PixelAction("push", 4, 60, 100), 0.8123) == "push at 90.0 deg, pixel (row 60, col 100), Q 0.812"
    assert action_label(PixelAction("grasp", 1, 0, 5)) == "grasp at 22.5 deg, pixel (row 0, col 5)"


def test_save_qmap_png(tmp_path, rng):
    scene = random_scene(rng)
    maps = {p: torch.rand(16, 224, 224) for p in ("move", "push", "grasp")}
    primitives = ("move", "push", "grasp")
    action = encode_action(primitives, "push", 4, 60, 100)  # rotation 4 = +90 deg = +row direction
    path = save_qmap_png(tmp_path / "q.png", scene, maps, action, primitives=primitives, scale=2)
    image = cv2.imread(str(path))
    assert image.shape == (HEADER_PX + 448 + FOOTER_PX, 3 * 448 + COLORBAR_PX, 3)
    panels = image[HEADER_PX : HEADER_PX + 448]
    push_panel = panels[:, 448:896]
    # The push arrow runs from the pixel toward increasing rows: white along column 100.5 * 2.
    col = 201
    along = push_panel[2 * 60 + 20 : 2 * 60 + 80, col - 1 : col + 2]
    assert (along.min(axis=-1) > 230).any(axis=1).mean() > 0.9
    # Nothing is drawn across the other panels at that place.
    grasp_panel = panels[:, 896:]
    assert not (grasp_panel[2 * 60 + 20 : 2 * 60 + 80, col - 1 : col + 2].min(axis=-1) > 250).all()
    # Titles, caption and colour bar carry text (bright pixels on their black ground).
    for strip in (image[:HEADER_PX, :448], image[-FOOTER_PX:, :1344], image[:, -COLORBAR_PX:]):
        assert (strip.max(axis=-1) > 200).sum() > 100
    # The colour bar runs from red (high Q) at the top to blue (low Q) at the bottom.
    bar = image[HEADER_PX + 5 : HEADER_PX + 448 + FOOTER_PX - 35, -COLORBAR_PX + 12 : -COLORBAR_PX + 28]
    top, bottom = bar[:10].reshape(-1, 3).mean(0), bar[-10:].reshape(-1, 3).mean(0)
    assert top[2] > top[0] + 50 and bottom[0] > bottom[2] + 50  # BGR: red on top, blue below


def test_save_qmap_png_accepts_decisions_and_single_primitive(tmp_path, rng):
    scene = random_scene(rng)
    scene_chw = dict(scene, color=np.ascontiguousarray(scene["color"].transpose(2, 0, 1)))
    path = save_qmap_png(
        tmp_path / "g.png", scene_chw, {"grasp": np.zeros((1, 16, 224, 224))}, PixelAction("grasp", 0, 10, 10), scale=1
    )
    assert cv2.imread(str(path)).shape == (HEADER_PX + 224 + FOOTER_PX, 224 + COLORBAR_PX, 3)
    with pytest.raises(ValueError, match="at least one"):
        save_qmap_png(tmp_path / "x.png", scene, {}, None)
    with pytest.raises(ValueError, match="colour heightmap"):
        save_qmap_png(
            tmp_path / "x.png", dict(scene, color=scene["color"][..., :2]), {"grasp": np.zeros((16, 224, 224))}
        )
    with pytest.raises(ValueError, match="'push' has no Q map"):
        save_qmap_png(tmp_path / "x.png", scene, {"grasp": np.zeros((16, 224, 224))}, PixelAction("push", 0, 1, 1))


def test_save_policy_qmaps_draws_every_branch_of_a_three_branch_net(tmp_path, rng, build_policy):
    """A randomly initialised three-branch net: a panel for move, push and grasp."""
    policy = build_policy(observation_space(), PixelActionSpace(PRIMITIVES))
    scene = random_scene(rng, occluded=False)
    path = save_policy_qmaps(tmp_path / "qmaps.png", policy, scene)
    image = cv2.imread(str(path))
    assert image.shape == (HEADER_PX + 448 + FOOTER_PX, 3 * 448 + COLORBAR_PX, 3)
    decision = policy.decide(scene)
    panel = PRIMITIVES.index(decision.primitive)
    # The chosen pixel is ringed in black on its primitive's panel.
    r, c = 2 * decision.row + 1, 448 * panel + 2 * decision.col + 1
    ring = image[HEADER_PX + max(0, r - 6) : HEADER_PX + r + 7, max(0, c - 6) : c + 7]
    assert (ring.max(axis=-1) < 40).any()


def _write_progress(path, iterations: int, rng) -> None:
    """A ``progress.csv`` as mpg-train writes it: loss from iteration 5 on, episodes of 3 motions."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = ["iteration,episode,primitive,loss,epsilon,target_grasped,num_motions"]
    for i in range(1, iterations + 1):
        loss = f"{rng.uniform(0.1, 1.0):.4f}" if i >= 5 else ""
        lines.append(f"{i},{(i - 1) // 3},grasp,{loss},{0.5 - 0.01 * i:.3f},{int(rng.random() < 0.4)},{(i - 1) % 3 + 1}")
    path.write_text("\n".join(lines) + "\n")


def test_plot_run_shorter_than_the_window(tmp_path, rng):
    from mpg_agents.learning.plotting import plot_run, read_progress, window_success

    _write_progress(tmp_path / "run" / "progress.csv", 30, rng)
    data = read_progress(tmp_path / "run" / "progress.csv")
    x, y = window_success(data, 200)
    assert x.tolist() == [30]  # one point at the run's end, not at iteration 200
    assert y[0] == data["target_grasped"].mean()
    x, _ = window_success(data, 12)
    assert x.tolist() == [12, 24, 30]
    with pytest.raises(ValueError, match="window"):
        window_success(data, 0)
    out = plot_run(tmp_path / "run", window=200)
    image = cv2.imread(str(out))
    assert image is not None and image.shape[0] > 500


def test_window_episode_success_counts_each_finished_episode_once_at_its_end(tmp_path):
    from mpg_agents.learning.plotting import plot_compare, read_progress, window_episode_success

    # episodes 0..3 end at iterations 2 (success), 3 (failure), 6 (success); episode 3 is unfinished
    rows = [(1, 0, 0), (2, 0, 1), (3, 1, 0), (4, 2, 0), (5, 2, 0), (6, 2, 1), (7, 3, 0)]
    path = tmp_path / "run" / "Stage5" / "progress.csv"
    path.parent.mkdir(parents=True)
    path.write_text("iteration,episode,primitive,loss,epsilon,target_grasped,num_motions,is_success\n"
                    + "".join(f"{i},{e},grasp,0.1,0.5,{s},1,{s}\n" for i, e, s in rows))
    data = read_progress(path)
    x, y = window_episode_success(data, 3)
    assert x.tolist() == [3, 6] and y.tolist() == [0.5, 1.0]
    x, y = window_episode_success(data, 2)
    assert x.tolist() == [2, 4, 6] and y.tolist() == [1.0, 0.0, 1.0]
    with pytest.raises(ValueError, match="window"):
        window_episode_success(data, 0)
    with pytest.raises(ValueError, match="is_success"):
        window_episode_success({k: v for k, v in data.items() if k != "is_success"}, 3)
    out = plot_compare([("a", tmp_path / "run"), ("b", tmp_path / "run" / "Stage5")], "Stage5", tmp_path / "cmp.png", 3)
    image = cv2.imread(str(out))
    assert image is not None and image.shape[1] > image.shape[0]  # two panels side by side
