"""How the learner explores (paper, Training Details and Simulation Experiments).

- epsilon-greedy with epsilon annealed linearly from ``start`` to ``end``;
- an exploratory action is a random rotation at a random pixel where the primitive can
  matter: move and grasp inside the target's bounding rectangle (grasp on the target's own
  pixels for a network that grasps only there), push within 25 pixels (5 cm) of it; with the
  ``max_q`` coordination the primitive is random too;
- after ``heuristic_after_failed_grasps`` failed grasps in a row the next grasp is the
  pixel-only heuristic grasp (:mod:`mpg_envs.policies.pixel_heuristic`), a training aid of the paper.

One seeded generator drives every random choice; its state is saved with the run.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from mpg_agents.acting.decision import Decision
from mpg_agents.network.regions import footprint_top, grasp_pixels
from mpg_envs.grid.actions import encode_action
from mpg_envs.grid.primitive_specs import GRASP, MOVE, PUSH
from mpg_envs.grid.workspace import NUM_ROTATIONS
from mpg_envs.policies.pixel_heuristic import heuristic_grasp

PUSH_REACH_PX = 25
"""How far (pixels, 2 mm each) around the target's rectangle an exploratory push may start."""


@dataclass(frozen=True)
class TakenAction:
    """An action a training step takes, how it was chosen and the Q it was chosen by: the agent's
    greedy :class:`~mpg_agents.acting.decision.Decision`, or exploration's or the heuristic's
    action in its place (:meth:`Explorer.choose`)."""

    action: int
    primitive: str
    chosen_by: str  # "greedy", "explore" or "heuristic" (progress.csv's column "how")
    q_value: float = float("nan")


def linear_epsilon(iteration: int, start: float, end: float, decay_steps: int) -> float:
    """Epsilon after ``iteration`` iterations: ``start`` to ``end`` linearly over ``decay_steps``."""
    frac = min(1.0, iteration / max(1, decay_steps))
    return start + frac * (end - start)


class Explorer:
    """Turns the policy's greedy decision into the action taken (exploration and training aids).

    Args:
        primitives: the env's primitives (the action encoding).
        rng: the run's generator.
        heuristic_after_failed_grasps: failed grasps in a row before the heuristic grasp (0: never).
        random_primitive: explore the primitive too (the ``max_q`` coordination).
        grasp_on_target: explore grasps on the target's footprint only (for a network whose
            ``grasp_region`` is ``"target"`` or ``"visible"``: it may only grasp there greedily either).
        target_margin_px: with ``grasp_on_target``, those pixels grown or shrunk as the
            network's (:func:`mpg_agents.network.regions.target_pixels`), so exploration grasps where a
            greedy grasp may.
        visible_band_m: with ``grasp_on_target``, explore grasps only where the footprint
            shows the target itself (within this many metres of its lowest surface:
            :func:`mpg_agents.network.regions.footprint_bottom`), for a network whose
            ``grasp_region`` is ``"visible"``; ``None``: the whole footprint.
        move_band_m: explore moves on the target footprint's top (within this many metres of
            its highest point: :func:`mpg_agents.network.regions.footprint_top`), for a network whose
            ``move_region`` is ``"top"``; ``None``: anywhere in the rectangle.
        usable: the primitives a random primitive is drawn from (default: ``primitives``; a
            network without a move branch never explores a move).
    """

    def __init__(
        self,
        primitives: Sequence[str],
        rng: np.random.Generator,
        heuristic_after_failed_grasps: int = 2,
        random_primitive: bool = False,
        grasp_on_target: bool = False,
        usable: Sequence[str] | None = None,
        target_margin_px: int = 0,
        move_band_m: float | None = None,
        visible_band_m: float | None = None,
    ) -> None:
        self.primitives = tuple(primitives)
        self.usable = tuple(usable) if usable is not None else self.primitives
        if not set(self.usable) <= set(self.primitives):
            raise ValueError(f"usable primitives {self.usable} must be among the env's {self.primitives}")
        self.rng = rng
        self.heuristic_after_failed_grasps = heuristic_after_failed_grasps
        self.random_primitive = random_primitive
        self.grasp_on_target = grasp_on_target
        self.target_margin_px = int(target_margin_px)
        self.move_band_m = move_band_m
        self.visible_band_m = visible_band_m

    def choose(
        self, obs: Mapping[str, np.ndarray], decision: Decision, epsilon: float, failed_grasps_in_a_row: int
    ) -> TakenAction:
        """The action for ``obs`` given the policy's greedy ``decision`` (its primitive is kept
        unless :attr:`random_primitive`)."""
        primitive = decision.primitive
        n = self.heuristic_after_failed_grasps
        if primitive == GRASP and n and failed_grasps_in_a_row >= n and obs["mask"].any():
            rot, row, col = heuristic_grasp(obs)
            return TakenAction(encode_action(self.primitives, GRASP, rot, row, col), GRASP, "heuristic")
        if self.rng.random() < epsilon:
            if self.random_primitive:
                primitive = self.usable[int(self.rng.integers(len(self.usable)))]
            rot, row, col = self.explore_pixel(obs, primitive)
            return TakenAction(encode_action(self.primitives, primitive, rot, row, col), primitive, "explore")
        return TakenAction(int(decision.action), primitive, "greedy", float(decision.q_value))

    def explore_pixel(self, obs: Mapping[str, np.ndarray], primitive: str) -> tuple[int, int, int]:
        """A random ``(rotation, row, col)`` where ``primitive`` can matter.

        Move and grasp: inside the target's bounding rectangle (the rough mask); grasp on a
        target footprint pixel with :attr:`grasp_on_target` (only where the target shows with
        :attr:`visible_band_m`; grown or shrunk by :attr:`target_margin_px`); move on the
        footprint's top with :attr:`move_band_m`.
        Push: within :data:`PUSH_REACH_PX` of the rectangle. An empty mask falls back to any
        occupied pixel, then to any pixel.
        """
        mask = obs["mask"] > 0
        size = mask.shape[0]
        if primitive == GRASP and self.grasp_on_target and mask.any():
            depth = torch.as_tensor(np.asarray(obs["depth"], dtype=np.float32))[None]
            region = grasp_pixels(torch.from_numpy(mask[None]), depth, self.target_margin_px, self.visible_band_m)[0].numpy()
            on_target = np.argwhere(region)
            row, col = (int(v) for v in on_target[self.rng.integers(len(on_target))])
        elif primitive == MOVE and self.move_band_m is not None and mask.any():
            depth = torch.as_tensor(np.asarray(obs["depth"], dtype=np.float32))[None]
            on_top = np.argwhere(footprint_top(torch.from_numpy(mask[None]), depth, self.move_band_m)[0].numpy())
            row, col = (int(v) for v in on_top[self.rng.integers(len(on_top))])
        elif mask.any():
            rows, cols = np.nonzero(mask)
            pad = PUSH_REACH_PX if primitive == PUSH else 0
            r0, r1 = max(rows.min() - pad, 0), min(rows.max() + pad, size - 1)
            c0, c1 = max(cols.min() - pad, 0), min(cols.max() + pad, size - 1)
            row, col = int(self.rng.integers(r0, r1 + 1)), int(self.rng.integers(c0, c1 + 1))
        else:
            occupied = np.argwhere(obs["depth"] > 0.005)
            if len(occupied):
                row, col = (int(v) for v in occupied[self.rng.integers(len(occupied))])
            else:
                row, col = (int(v) for v in self.rng.integers(size, size=2))
        return int(self.rng.integers(NUM_ROTATIONS)), row, col
