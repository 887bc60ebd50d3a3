"""Why does an MPGNet's move lift nothing? Where and at which angle its moves close.

Runs a checkpoint greedily (its own coordination and Q*_g) on seeded episodes and, before each
move it makes, looks at the move in a copy of the simulation (each trial is run and undone,
:meth:`mpg_envs.tasks.episode_sim.EpisodeSim.try_primitive` on the env's ``sim``; the episode itself
is unchanged; :class:`MoveProbe`):

- what the move's pixel shows: bare table, the target, an occluder (an object seen over the
  target's footprint above the target's top, as the scripted oracle finds them) or another
  object (:func:`classify_pixel`);
- for a move on an object, the angle between the fingers' closing direction and the object's
  short axis (the footprint rectangle's), in degrees;
- whether the move lifts an object, whether any of the 8 grasp angles at the same pixel would,
  and whether the scripted oracle's first move of the topmost occluder would (its plan, tried
  the same way): what a better angle, or a better spot, would have bought.

Each trial costs a motion's simulation (about 0.3 s), ten per move. ``benchmarks/move_outcomes.py``
is its command line.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_agents.evaluation.evaluate import run_episodes
from mpg_agents.evaluation.policy_zoo import NetworkPolicy, make_network_policy
from mpg_envs.grid.grasp_geometry import GRASP_ROTATIONS, angle_gap, footprint_rect, other_grasp_angles
from mpg_envs.grid.primitive_specs import MOVE
from mpg_envs.policies.oracle import OraclePolicy

ON_WHAT = ("table", "target", "occluder", "other")
"""What a move's pixel shows."""

ANGLE_LIMIT_DEG = 25.0
"""Moves closing within this of the object's short axis count as on-axis in the summary."""


def classify_pixel(object_id: int, target: int, occluders: list[int]) -> str:
    """What a pixel showing ``object_id`` (-1: the table) is to the move: one of :data:`ON_WHAT`."""
    if object_id < 0:
        return "table"
    if object_id == target:
        return "target"
    return "occluder" if object_id in occluders else "other"


class MoveProbe:
    """Acts as an MPGNet policy does, and records a look at each of its moves before it is made."""

    def __init__(self, net: NetworkPolicy, env: gym.Env) -> None:
        self.net, self.env = net, env
        self.oracle = OraclePolicy(env)  # its view of which object each pixel shows, its move plans
        self.records: list[dict[str, Any]] = []

    def reset(self) -> None:
        self.net.reset()

    def act(self, obs) -> int:
        decision = self.net.policy.decide(obs)
        if decision.primitive == MOVE:
            self.records.append(self._look(obs, decision.rotation, decision.row, decision.col))
        return int(decision.action)

    def _lifts(self, rotation: int, row: int, col: int, depth: np.ndarray, obj: int | None = None) -> bool:
        u: Any = self.env.unwrapped  # the MPG env (gym.Env does not declare its attributes)
        result = u.sim.try_primitive(MOVE, rotation, row, col, depth, u.target)
        return bool(result.lifted and (obj is None or result.grasped_object == obj))

    def _look(self, obs, rotation: int, row: int, col: int) -> dict[str, Any]:
        u: Any = self.env.unwrapped
        oracle = self.oracle
        world, target, depth = u.world, u.target, np.asarray(obs["depth"])
        _, ids = oracle.view(world)
        occluders = oracle.occluders(world, target, depth, ids, obs["mask"])
        obj = int(ids[row, col])
        record: dict[str, Any] = {"on": classify_pixel(obj, target, occluders), "angle_off_deg": None}
        if obj >= 0:
            _, _, short_dir = footprint_rect(world.object_vertices(obj)[:, :2])
            record["angle_off_deg"] = math.degrees(angle_gap(rotation * math.pi / GRASP_ROTATIONS, short_dir))
        record["lifted"] = self._lifts(rotation, row, col, depth)
        record["any_angle_lifts"] = record["lifted"] or any(
            self._lifts(k, row, col, depth) for k in other_grasp_angles(rotation)
        )
        record["oracle_lifts"] = None
        if occluders:
            plans = oracle.grasp_plans(u, occluders[0], depth, ids, require_fit=False)
            record["oracle_lifts"] = bool(plans) and self._lifts(
                plans[0].rotation, plans[0].row, plans[0].col, depth, occluders[0]
            )
        return record


def summarise_moves(records: list[dict[str, Any]], angle_limit_deg: float = ANGLE_LIMIT_DEG) -> dict[str, Any]:
    """Counts: moves and lifts per :data:`ON_WHAT`, on-axis and off-axis moves on an occluder
    and their lifts, moves where some angle at the pixel lifts, and where the oracle's does."""
    if not records:
        raise ValueError("no moves were made: nothing to summarise")
    on_occluder = [r for r in records if r["on"] == "occluder"]
    near = [r for r in on_occluder if r["angle_off_deg"] <= angle_limit_deg]
    far = [r for r in on_occluder if r["angle_off_deg"] > angle_limit_deg]
    with_oracle = [r for r in records if r["oracle_lifts"] is not None]
    return {
        "moves": len(records),
        "lifted": sum(r["lifted"] for r in records),
        "on": {k: sum(r["on"] == k for r in records) for k in ON_WHAT},
        "lifted_on": {k: sum(r["lifted"] for r in records if r["on"] == k) for k in ON_WHAT},
        "angle_limit_deg": angle_limit_deg,
        "occluder_on_axis": len(near),
        "occluder_on_axis_lifted": sum(r["lifted"] for r in near),
        "occluder_off_axis": len(far),
        "occluder_off_axis_lifted": sum(r["lifted"] for r in far),
        "any_angle_lifts": sum(r["any_angle_lifts"] for r in records),
        "oracle_tried": len(with_oracle),
        "oracle_lifts": sum(r["oracle_lifts"] for r in with_oracle),
    }


def move_records(
    policy_name: str,
    env_id: str,
    num_objects: int,
    episodes: int,
    seed: int,
    move_region: str | None = None,
    move_fingers: str | None = None,
) -> tuple[str, list[dict[str, Any]]]:
    """The policy's name and a look at every move of ``episodes`` greedy episodes (episode ``i``
    reset with ``seed + i``, as ``mpg-eval`` runs them); ``move_region`` and ``move_fingers``
    override the net's.

    Raises:
        ValueError: ``policy_name`` is not an MPGNet checkpoint (or ``shipped``).
    """
    env = gym.make(env_id, num_objects=num_objects)
    net = make_network_policy(policy_name, env, move_region=move_region, move_fingers=move_fingers)
    probe = MoveProbe(net, env)
    run_episodes(probe, env, range(episodes), seed)
    env.close()
    return net.name, probe.records
