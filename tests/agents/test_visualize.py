"""Q-map PNG: one panel per primitive, the chosen action drawn on its panel."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from mpg_agents.visualize import save_qmap_png
from mpg_envs.actions import PixelAction, encode_action

from .scenes import random_scene


def test_save_qmap_png(tmp_path, rng):
    scene = random_scene(rng)
    maps = {p: torch.rand(16, 224, 224) for p in ("move", "push", "grasp")}
    primitives = ("move", "push", "grasp")
    action = encode_action(primitives, "push", 4, 60, 100)  # rotation 4 = +90 deg = +row direction
    path = save_qmap_png(tmp_path / "q.png", scene, maps, action, primitives=primitives, scale=2)
    image = cv2.imread(str(path))
    assert image.shape == (448, 3 * 448, 3)
    push_panel = image[:, 448:896]
    # The push arrow runs from the pixel toward increasing rows: white along column 100.5 * 2.
    col = 201
    along = push_panel[2 * 60 + 20 : 2 * 60 + 80, col - 1 : col + 2]
    assert (along.min(axis=-1) > 230).any(axis=1).mean() > 0.9
    # Nothing is drawn across the other panels at that place.
    grasp_panel = image[:, 896:]
    assert not (grasp_panel[2 * 60 + 20 : 2 * 60 + 80, col - 1 : col + 2].min(axis=-1) > 250).all()


def test_save_qmap_png_accepts_decisions_and_single_primitive(tmp_path, rng):
    scene = random_scene(rng)
    scene_chw = dict(scene, color=np.ascontiguousarray(scene["color"].transpose(2, 0, 1)))
    path = save_qmap_png(
        tmp_path / "g.png", scene_chw, {"grasp": np.zeros((1, 16, 224, 224))}, PixelAction("grasp", 0, 10, 10), scale=1
    )
    assert cv2.imread(str(path)).shape == (224, 224, 3)
    with pytest.raises(ValueError, match="at least one"):
        save_qmap_png(tmp_path / "x.png", scene, {}, None)
    with pytest.raises(ValueError, match="colour heightmap"):
        save_qmap_png(
            tmp_path / "x.png", dict(scene, color=scene["color"][..., :2]), {"grasp": np.zeros((16, 224, 224))}
        )
