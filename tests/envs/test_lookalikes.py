"""The look-alike rule of exemplar scenes (mpg_envs.scenes.lookalikes), on hand-made scenes."""

from __future__ import annotations

import numpy as np
import pytest

from mpg_envs.scenes.lookalikes import (
    PALETTE,
    exemplar_colours,
    rule_breaks,
    shape_key,
    shared_looks,
)


class Scripted:
    """A generator whose ``integers(n)`` answers a script (each value checked below ``n``)."""

    def __init__(self, answers):
        self.answers = list(answers)

    def integers(self, n):
        value = self.answers.pop(0)
        assert 0 <= value < n
        return value


def test_the_rule_drawn_by_hand():
    # Objects: 0 cube (target), 1 cube, 2 disc, 3 arch.
    shapes = ["cube", "cube", "disc", "arch"]
    # Target colour 4; the other cube picks index 4 among [0,1,2,3,5,...] -> colour 5; the disc
    # draws 7, the arch 2; neither drew 4, so one of the two (index 1 -> the arch) takes it.
    colours = exemplar_colours(shapes, 0, Scripted([4, 4, 7, 2, 1]))
    assert colours == (4, 5, 7, 4)
    assert rule_breaks(shapes, colours, 0) == []
    assert shared_looks(shapes, colours, 0, 1) == ("shape",)
    assert shared_looks(shapes, colours, 0, 3) == ("colour",)
    assert shared_looks(shapes, colours, 0, 2) == ()


def test_a_drawn_match_of_the_colour_is_kept_and_nothing_is_forced():
    shapes = ["a", "b", "b"]
    # Target colour 0; object 1 draws 0 itself: no forced draw follows (the script would run dry).
    assert exemplar_colours(shapes, 0, Scripted([0, 0, 3])) == (0, 0, 3)


def test_scenes_of_one_shape_only_take_other_colours():
    shapes = ["a"] * 4
    colours = exemplar_colours(shapes, 2, np.random.default_rng(0))
    assert all(c != colours[2] for i, c in enumerate(colours) if i != 2)
    assert rule_breaks(shapes, colours, 2) == []


def test_the_rule_holds_on_random_scenes():
    for seed in range(300):
        rng = np.random.default_rng(seed)
        n = int(rng.integers(1, 31))
        shapes = [int(s) for s in rng.integers(8, size=n)]
        target = int(rng.integers(n))
        colours = exemplar_colours(shapes, target, rng)
        assert len(colours) == n and all(0 <= c < len(PALETTE) for c in colours)
        assert rule_breaks(shapes, colours, target) == [], seed


def test_rule_breaks_names_both_breaks():
    assert rule_breaks(["a", "a", "b"], [1, 1, 2], 0) == [
        "object 1 has the target's shape and colour",
        "no object of another shape has the target's colour",
    ]


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="target must be an object index in 0..1"):
        exemplar_colours(["a", "b"], 2, np.random.default_rng(0))
    with pytest.raises(ValueError, match="at least 2 colours"):
        exemplar_colours(["a", "b"], 0, np.random.default_rng(0), palette_size=1)


def test_shape_key_is_the_set_and_the_name(blocks):
    cube = blocks["cube"]
    assert shape_key(cube) == ("blocks", "cube")
    assert shape_key(cube) != shape_key(blocks["disc"])
