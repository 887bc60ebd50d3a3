"""The best actions of a Q map at places apart (the learner's move trials)."""

from __future__ import annotations

import pytest
import torch

from mpg_agents.acting.decision import spaced_best

INF = float("inf")


def _map() -> torch.Tensor:
    q = torch.full((2, 5, 6), -INF)
    q[0, 1, 1] = 3.0  # the best
    q[1, 1, 2] = 2.5  # beside the best: one pixel to its right
    q[1, 3, 0] = 2.0
    q[0, 4, 5] = 1.0
    return q


def test_the_best_first_then_the_best_outside_the_spacing():
    # (1, 2) is 1 pixel from (1, 1): within 1.5, so the next place is (3, 0) at its rotation 1.
    assert spaced_best(_map(), 3, 1.5) == [(0, 1, 1), (1, 3, 0), (0, 4, 5)]


def test_the_taken_pixel_and_its_neighbours_are_skipped():
    assert spaced_best(_map(), 5, 1.5, taken=(1, 1)) == [(1, 3, 0), (0, 4, 5)]  # only two finite places left


def test_spacing_zero_ranks_every_finite_pixel_once():
    q = _map()
    q[1, 1, 1] = 0.5  # a second rotation at the best pixel: the pixel counts once, at its best rotation
    assert spaced_best(q, 10, 0.0) == [(0, 1, 1), (1, 1, 2), (1, 3, 0), (0, 4, 5)]


def test_an_all_minus_inf_map_gives_nothing():
    assert spaced_best(torch.full((1, 3, 3), -INF), 2, 1.0) == []


@pytest.mark.parametrize("args, message", [((torch.zeros(3, 3), 1, 1.0), "q_map must be"), ((torch.zeros(1, 3, 3), -1, 1.0), "k and spacing_px")])
def test_bad_input_is_named(args, message):
    with pytest.raises(ValueError, match=message):
        spaced_best(*args)
