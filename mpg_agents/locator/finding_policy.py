"""A mask-reading policy run where the target is named by an exemplar: the locator finds it.

:class:`FindingPolicy` wraps a policy that reads the target's ``mask`` and ``occluded`` flag
(MPGNet, :class:`~mpg_agents.evaluation.policy_zoo.NetworkPolicy`). On an exemplar-mode
observation the :class:`~mpg_agents.locator.locator.TargetLocator` locates the target; where it
is seen, the wrapped policy gets the located pixels as its mask and the cover estimated from
them (:func:`~mpg_agents.locator.cover.estimate_occluded`); while it is not seen, the wrapped
policy is pointed at where it may hide (:func:`~mpg_agents.locator.cover.search_mask`, flagged
covered), so it moves or pushes what stands there and the locator looks again. A located object
that fits the exemplar worse than the locator's ``min_fit`` (by the ``"template"`` snapping) is
flagged covered the first ``rule.misfit_motions`` times in an episode: the net uncovers around it
before it may grasp it. An observation that has a ``mask`` (mask and visible modes) passes through
unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from mpg_agents.locator.cover import CoverRule, estimate_occluded, search_mask
from mpg_agents.locator.locator import Location, TargetLocator
from mpg_envs.tasks.target_spec import target_observation_space


class MaskedView(gym.ObservationWrapper):
    """``env`` as a mask-reading policy expects it: its observation space is the visible mode's
    (colour, depth, ``mask``, ``occluded``); only the spaces and the env's config are read."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.observation_space = target_observation_space("visible", env.unwrapped.config.workspace)  # type: ignore[attr-defined]

    def observation(self, observation: Any) -> Any:
        return observation


class FindingPolicy:
    """``inner`` (a policy reading ``mask`` and ``occluded``) acting on what ``locator`` finds,
    judging cover and searching by ``rule`` (default: the locator's); ``last_location`` is the
    last exemplar-mode decision's :class:`Location` (``None`` in the other modes), ``searching``
    whether that decision searched."""

    def __init__(self, inner: Any, locator: TargetLocator, rule: CoverRule | None = None):
        self.inner = inner
        self.locator = locator
        self.rule = locator.rule if rule is None else rule
        self.name = f"{inner.name} + locator"
        self.primitives = getattr(inner, "primitives", ())
        self.last_location: Location | None = None
        self.searching = False
        self.misfits = 0  # this episode's decisions that took a misfit for covered

    def reset(self) -> None:
        self.last_location, self.searching, self.misfits = None, False, 0
        self.inner.reset()

    def located_observation(self, obs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The mask-mode observation the wrapped policy gets for the exemplar-mode ``obs``."""
        location = self.locator.locate(obs)
        self.last_location = location
        self.searching = not location.seen
        depth = np.asarray(obs["depth"])
        if location.seen:
            mask, occluded = location.mask, estimate_occluded(depth, location.mask, obs["query_depth"], self.rule)
            misfit = location.fit is not None and location.fit < self.locator.min_fit
            if misfit and not occluded and self.misfits < self.rule.misfit_motions:
                # Not shaped like the exemplar: uncover around it before a grasp, the first few times.
                occluded, self.misfits = True, self.misfits + 1
        else:
            mask, occluded = search_mask(depth, obs["query_depth"], self.rule), True
        return {
            "color": obs["color"],
            "depth": obs["depth"],
            "mask": mask.astype(np.uint8),
            "occluded": np.array([int(occluded)], dtype=np.int8),
        }

    def act(self, obs: Mapping[str, np.ndarray]) -> int:
        if "mask" in obs:
            return int(self.inner.act(obs))
        return int(self.inner.act(self.located_observation(obs)))

    def save_qmaps(self, path: Any, obs: Mapping[str, np.ndarray]) -> None:
        """The wrapped policy's Q maps on the located observation."""
        self.inner.save_qmaps(path, obs if "mask" in obs else self.located_observation(obs))
