"""Does a grasp net's Q tell the grasps that take the target from those that do not?

Runs a checkpoint greedily (its own coordination and Q*_g) on seeded episodes and records every
grasp it executes (:func:`grasp_records`): the grasp's Q (the value the decision maximised), the
occlusion bit before it, and what it did (took the target, took another object, or held
nothing, with the env's failure kind). :func:`summarise` gives the counts, the share that took
the target with the target covered and uncovered, the share per Q quartile, and the ROC AUC of
Q as a predictor of a target grasp (0.5: Q says nothing; 1: every target grasp scores above
every other grasp). A Q*_g rule can only send the hopeless grasps to a move or a push when this
AUC is well above 0.5. The moves and pushes of the same episodes are tallied too
(:func:`summarise_motions`: how many found the target covered, how many left it uncovered, and
how many moves lifted nothing), so the Q*_g rule's other branch is measured as well. With angle
trials each grasp is also tried, before it is made, at the other gripper orientations at its
pixel (``MPGEnv.try_step``, undone; the episode is unchanged), counting the grasps that missed
the target where another angle would have taken it. Each grasp's finger blocking is recorded
too (:func:`mpg_envs.grid.grasp_geometry.fingers_blocked`), with the share of free (``<= 0``) and
blocked grasps that took the target and the ROC AUC of minus the blocking: what a grasp's
geometry alone says.

``benchmarks/grasp_q_outcomes.py`` is its command line.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_agents.acting.spaces import finger_geometry
from mpg_agents.evaluation.evaluate import run_episodes
from mpg_agents.evaluation.policy_zoo import NetworkPolicy, make_network_policy
from mpg_envs.grid.grasp_geometry import other_grasp_angles
from mpg_envs.grid.primitive_specs import GRASP, MOVE, PUSH


def roc_auc(scores: Sequence[float] | np.ndarray, labels: Sequence[bool] | np.ndarray) -> float:
    """Probability that a positive's score exceeds a negative's (ties count half).

    The Mann-Whitney form of the area under the ROC curve; NaN when either class is empty.
    """
    s = np.asarray(scores, dtype=float)
    y = np.asarray(labels, dtype=bool)
    if s.shape != y.shape or s.ndim != 1:
        raise ValueError(f"scores and labels must be 1-D of one length, got {s.shape} and {y.shape}")
    pos, neg = s[y], s[~y]
    if len(pos) == 0 or len(neg) == 0:
        return float("nan")
    greater = (pos[:, None] > neg[None, :]).sum()
    ties = (pos[:, None] == neg[None, :]).sum()
    return float((greater + 0.5 * ties) / (len(pos) * len(neg)))


class GraspProbe:
    """Acts as an MPGNet policy does, and remembers the Q of the decision it just made, its
    grasp's finger blocking and, given ``env``, whether another orientation of its grasp would
    have taken the target (tried and undone)."""

    def __init__(self, network_policy: NetworkPolicy, env: gym.Env | None = None):
        self.net, self.env = network_policy, env
        self.q = float("nan")
        self.blocked = float("nan")
        self.other_angle_takes: bool | None = None

    def reset(self) -> None:
        self.net.reset()

    def act(self, obs) -> int:
        decision = self.net.policy.decide(obs)
        self.q = float(decision.q_value)
        self.other_angle_takes = None
        self.blocked = float("nan")
        if decision.primitive == GRASP:
            geometry = self.net.policy.q_net.mpgnet.geometry or finger_geometry()  # the env's, when the net has it
            blocked = geometry.blocked(np.asarray(obs["depth"])[None], self.net.policy.net_config.num_rotations)[0]
            self.blocked = float(blocked[decision.rotation, decision.row, decision.col])
        if self.env is not None and decision.primitive == GRASP:
            u: Any = self.env.unwrapped  # the MPG env (gym.Env does not declare its attributes)
            self.other_angle_takes = any(
                u.try_step(u.action_space.encode(GRASP, k, decision.row, decision.col))[4]["target_grasped"]
                for k in other_grasp_angles(decision.rotation)
            )
        return int(decision.action)


def grasp_records(
    policy_name: str,
    env_id: str,
    num_objects: int,
    episodes: int,
    seed: int,
    angle_trials: bool = False,
    grasp_fingers: str | None = None,
) -> tuple[str, float, list[dict], list[dict]]:
    """The policy's name, its Q*_g, every grasp and every move or push of ``episodes`` greedy
    episodes (episode ``i`` reset with ``seed + i``, as ``mpg-eval`` runs them).

    Raises:
        ValueError: ``policy_name`` is not an MPGNet checkpoint (or ``shipped``).
    """
    env = gym.make(env_id, num_objects=num_objects)
    policy = make_network_policy(policy_name, env, **({"grasp_fingers": grasp_fingers} if grasp_fingers else {}))
    if policy.policy.q_star is None:
        raise ValueError(f"{policy.name} has no Q*_g to compare its grasp Q with: calibrate it (mpg-calibrate) first")
    acting = GraspProbe(policy, env if angle_trials else None)
    records: list[dict] = []
    others: list[dict] = []

    def on_step(index: int, reward: float, info: dict) -> None:
        if info["primitive"] != GRASP:
            others.append(
                {
                    "seed": seed + index,
                    "primitive": info["primitive"],
                    "covered_before": bool(info["occluded_before"]),
                    "covered_after": bool(info["occluded"]),
                    "held_nothing": info["primitive"] == MOVE and not info["lifted"],
                }
            )
        else:
            records.append(
                {
                    "seed": seed + index,
                    "q": acting.q,
                    "occluded": bool(info["occluded_before"]),
                    "target": bool(info["target_grasped"]),
                    "wrong": bool(info["wrong_grasp"]),
                    "failure": info["grasp_failure"],
                    "other_angle_takes": acting.other_angle_takes,
                    "blocked": acting.blocked,
                }
            )

    run_episodes(acting, env, range(episodes), seed, on_step=on_step)
    env.close()
    return policy.name, policy.policy.q_star, records, others


def summarise_motions(others: list[dict]) -> dict:
    """Per primitive (move, push): how many, how many found the target covered, how many of
    those left it uncovered, and how many moves lifted nothing."""
    out = {}
    for primitive in (MOVE, PUSH):
        mine = [r for r in others if r["primitive"] == primitive]
        covered = [r for r in mine if r["covered_before"]]
        out[primitive] = {
            "count": len(mine),
            "covered_before": len(covered),
            "uncovered_it": sum(not r["covered_after"] for r in covered),
            "held_nothing": sum(r["held_nothing"] for r in mine),
        }
    return out


def summarise(records: list[dict], q_star: float) -> dict:
    """Counts, target-grasp shares by occlusion and Q quartile, and the AUC of Q."""
    if not records:
        raise ValueError("no grasps were executed: nothing to summarise")
    q = np.array([r["q"] for r in records])
    took = np.array([r["target"] for r in records])
    occluded = np.array([r["occluded"] for r in records])
    edges = np.quantile(q, [0.25, 0.5, 0.75])
    quartile = np.searchsorted(edges, q, side="right")
    share = lambda sel: float(took[sel].mean()) if sel.any() else float("nan")  # noqa: E731
    failures = Counter(r["failure"] for r in records if r["failure"] is not None)
    return {
        "grasps": len(records),
        "target": int(took.sum()),
        "wrong": int(sum(r["wrong"] for r in records)),
        "failures": dict(failures),
        "target_share_covered": share(occluded),
        "covered": int(occluded.sum()),
        "target_share_uncovered": share(~occluded),
        "uncovered": int((~occluded).sum()),
        "q_quartile_edges": [float(e) for e in edges],
        "target_share_per_q_quartile": [share(quartile == k) for k in range(4)],
        "q_auc": roc_auc(q, took),
        "q_star": q_star,
        "target_share_q_at_least_q_star": share(q >= q_star),
        "q_at_least_q_star": int((q >= q_star).sum()),
        **summarise_angles(records),
        **summarise_fingers(records),
    }


def summarise_fingers(records: list[dict]) -> dict:
    """With finger blocking recorded: how many grasps had both fingers land free (``<= 0``),
    the share of free and blocked grasps that took the target, and the ROC AUC of minus the
    blocking as a predictor of a target grasp (empty without blocking)."""
    known = [r for r in records if r.get("blocked") is not None and np.isfinite(r["blocked"])]
    if not known:
        return {}
    blocked = np.array([r["blocked"] for r in known])
    took = np.array([r["target"] for r in known])
    free = blocked <= 0.0
    share = lambda sel: float(took[sel].mean()) if sel.any() else float("nan")  # noqa: E731
    return {
        "fingers_free": int(free.sum()),
        "target_share_fingers_free": share(free),
        "target_share_fingers_blocked": share(~free),
        "fingers_auc": roc_auc(-blocked, took),
    }


def summarise_angles(records: list[dict]) -> dict:
    """With angle trials: of the grasps that missed the target, covered and uncovered, how many
    had another orientation at the same pixel that would have taken it (empty without trials)."""
    tried = [r for r in records if r.get("other_angle_takes") is not None]
    if not tried:
        return {}
    out = {}
    for name, covered in (("covered", True), ("uncovered", False)):
        missed = [r for r in tried if r["occluded"] == covered and not r["target"]]
        out[f"missed_{name}"] = len(missed)
        out[f"missed_{name}_other_angle_takes"] = sum(r["other_angle_takes"] for r in missed)
    return out
