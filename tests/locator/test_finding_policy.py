"""What the finding policy hands the mask-reading net, with a stand-in locator (no network)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from mpg_agents.locator.cover import CoverRule
from mpg_agents.locator.finding_policy import FindingPolicy
from mpg_agents.locator.locator import Location


class _Locator:
    """Finds a whole 10 x 10 object (nothing higher beside it) with the given ``fit``."""

    def __init__(self, fit: float | None, misfit_motions: int):
        self.fit, self.min_fit = fit, 0.5
        self.rule = CoverRule(area_share=0.5, search="empty", misfit_motions=misfit_motions)

    def locate(self, obs: dict[str, np.ndarray]) -> Location:
        mask = np.zeros((40, 40), np.uint8)
        mask[10:20, 10:20] = 1
        return Location(mask.astype(np.float32), mask, True, 1.0, self.fit)


class _Net:
    name, primitives = "net", ()

    def __init__(self) -> None:
        self.seen: list[dict[str, Any]] = []

    def reset(self) -> None:
        pass

    def act(self, obs: dict[str, Any]) -> int:
        self.seen.append(obs)
        return 0


def _obs() -> dict[str, np.ndarray]:
    depth = np.zeros((40, 40), np.float32)
    depth[10:20, 10:20] = 0.03
    return {"color": np.zeros((40, 40, 3), np.uint8), "depth": depth, "query_color": np.zeros((40, 40, 3), np.uint8), "query_depth": depth}


@pytest.mark.parametrize("fit, covered", [(0.2, [1, 1, 0, 0]), (0.9, [0, 0, 0, 0]), (None, [0, 0, 0, 0])])
def test_a_misfit_is_taken_as_covered_the_first_times_in_an_episode(fit: float | None, covered: list[int]):
    net, locator = _Net(), _Locator(fit, misfit_motions=2)
    policy = FindingPolicy(net, locator)  # type: ignore[arg-type]
    for _ in range(4):
        policy.act(_obs())
    assert [int(o["occluded"][0]) for o in net.seen] == covered  # uncovered all along: whole, nothing on it
    policy.reset()
    policy.act(_obs())
    assert int(net.seen[-1]["occluded"][0]) == covered[0]  # a new episode counts afresh


def test_a_negative_count_is_refused():
    with pytest.raises(ValueError, match="misfit_motions"):
        CoverRule(misfit_motions=-1)
