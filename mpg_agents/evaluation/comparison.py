"""Two policies on the same episodes: paired differences of the paper's metrics.

``mpg-eval`` resets episode ``i`` with ``seed + i``, so two policies evaluated with the same
env, object count and seeds meet the same scenes. Comparing their per-episode results pair by
pair removes the scenes' own difficulty from the comparison (on this benchmark the seed set
moves a cell by more than a method does), and gives much narrower intervals than two
independent 95% intervals side by side. The intervals are percentile bootstraps over the
episode pairs (:func:`~mpg_agents.evaluation.stats.bootstrap_mean_interval` of the per-pair differences).

The same seed makes another scene, and the same action another motion, on another MuJoCo major
version (:mod:`mpg_envs.simulation.mujoco_version`), so files of different major versions are
not pooled, and two sides of different major versions are compared only when asked to
(``across_mujoco``: what the MuJoCo version itself changes). A file written before the MuJoCo
version was recorded (its ``versions`` without ``"mujoco"``) was measured on MuJoCo 3.x and
reads as ``"3.x"``.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import mpg_envs  # noqa: F401  (registers the ids same_scenes reads)
from mpg_agents.evaluation.stats import bootstrap_mean_interval
from mpg_envs.grid.actions import PRIMITIVES
from mpg_envs.simulation.mujoco_version import (
    UNRECORDED_MUJOCO,
    MuJoCoVersionError,
    check_one_mujoco,
    mujoco_major,
    recorded_mujoco,
)


@dataclass(frozen=True)
class EvalRecords:
    """The episodes of one policy in one cell, from one or more ``mpg-eval --json`` files."""

    policy: str
    env_id: str
    num_objects: int | None
    by_seed: dict[int, dict[str, Any]]
    mujoco: str = UNRECORDED_MUJOCO
    """The MuJoCo version the files record (``"<major>.x"`` when they name several of one major)."""


def load_eval_records(paths: Sequence[str | Path]) -> EvalRecords:
    """Read ``mpg-eval --json`` files of one policy in one cell (e.g. seed blocks run apart).

    Raises:
        ValueError: no file, files of different policies, envs or object counts, or a seed
            that appears twice.
        MuJoCoVersionError: files of different MuJoCo major versions.
    """
    if not paths:
        raise ValueError("no eval JSON file given")
    policy = env_id = None
    num_objects: int | None = None
    by_seed: dict[int, dict[str, Any]] = {}
    mujoco: dict[str, str] = {}
    for i, path in enumerate(paths):
        data = json.loads(Path(path).read_text())
        if not isinstance(data.get("records"), list):
            raise ValueError(
                f"{path} is not an episode evaluation (`mpg-eval --env ... --json`): its records are "
                f"{'per case (a `--cases` run)' if isinstance(data.get('records'), dict) else 'missing'}; "
                "paired comparisons take episode evaluations of one env and object count"
            )
        cell = (_policy_file(data["policy"]), data["env_id"], data.get("num_objects"))
        if i == 0:
            policy, env_id, num_objects = cell
        elif cell != (policy, env_id, num_objects):
            raise ValueError(f"{path} is {cell}, the first file {(policy, env_id, num_objects)}: one policy and cell per side")
        mujoco[str(path)] = recorded_mujoco(data.get("versions"))
        for record in data["records"]:
            seed = int(record["seed"])
            if seed in by_seed:
                raise ValueError(f"episode seed {seed} appears twice (in {path})")
            by_seed[seed] = record
    major = check_one_mujoco(mujoco, "pooling these files")
    found = set(mujoco.values())
    version = found.pop() if len(found) == 1 else f"{major}.x"
    return EvalRecords(str(policy), str(env_id), num_objects, by_seed, version)


def _policy_file(name: str) -> str:
    """``mpg-eval`` names a policy by its file; ``--policy shipped`` adds a ``shipped:`` prefix."""
    return name.removeprefix("shipped:")


@dataclass(frozen=True)
class PairedComparison:
    """A minus B over the episodes both played (rates as fractions, motions per episode)."""

    episodes: int
    success_a: float
    success_b: float
    success_difference: float
    success_interval: tuple[float, float]
    motions_a: float
    motions_b: float
    motions_difference: float
    motions_interval: tuple[float, float]
    fewer_motions_a: int
    fewer_motions_b: int
    primitive_differences: dict[str, float] = field(default_factory=dict)
    """Mean per-episode A minus B count of each primitive (they sum to the motions' difference);
    empty when a record does not say its primitives (files of older versions)."""
    mujoco: tuple[str, str] = (UNRECORDED_MUJOCO, UNRECORDED_MUJOCO)
    """The MuJoCo versions A and B were measured with."""

    @property
    def across_mujoco(self) -> bool:
        """Whether A and B ran on different MuJoCo major versions."""
        return mujoco_major(self.mujoco[0]) != mujoco_major(self.mujoco[1])

    def describe(self, name_a: str = "A", name_b: str = "B") -> str:
        lo, hi = self.success_interval
        mlo, mhi = self.motions_interval
        return (
            f"{self.episodes} paired episodes\n"
            f"  success  {name_a} {100 * self.success_a:.1f}%  {name_b} {100 * self.success_b:.1f}%  "
            f"difference {_points(self.success_difference)} points [{_points(lo)}, {_points(hi)}]\n"
            f"  motions  {name_a} {self.motions_a:.2f}  {name_b} {self.motions_b:.2f}  "
            f"difference {self.motions_difference:+.2f} [{mlo:+.2f}, {mhi:+.2f}]\n"
            f"  fewer motions: {name_a} in {self.fewer_motions_a} episodes, {name_b} in {self.fewer_motions_b}"
            + (
                f"\n  MuJoCo: {name_a} on {self.mujoco[0]}, {name_b} on {self.mujoco[1]}: different major "
                "versions, so the difference is the simulator's as much as the policies'"
                if self.across_mujoco
                else ""
            )
            + (
                "\n  motions by primitive, difference per episode: "
                + ", ".join(f"{p} {d:+.2f}" for p, d in self.primitive_differences.items())
                if self.primitive_differences
                else ""
            )
        )


def same_scenes(
    env_a: str, env_b: str, options_a: Mapping[str, Any] | None = None, options_b: Mapping[str, Any] | None = None
) -> bool:
    """Whether two registered ids, each with extra env keywords (``options_a``, ``options_b``; an
    extra one wins over the id's own), give the same episodes' scenes and observations, told
    apart only by how they name the target (``target_spec``): the hard track and its visible and
    exemplar versions, say. An id that is not registered matches only itself, with the same
    options."""
    own = [dict(options_a or {}), dict(options_b or {})]
    if env_a not in gym.registry or env_b not in gym.registry:
        return env_a == env_b and own[0] == own[1]
    kwargs = [
        {k: v for k, v in {**gym.registry[e].kwargs, **extra}.items() if k != "target_spec"}
        for e, extra in zip((env_a, env_b), own)
    ]
    return kwargs[0] == kwargs[1]


def compare_paired(a: EvalRecords, b: EvalRecords, seed: int = 0, across_mujoco: bool = False) -> PairedComparison:
    """A minus B on the episodes (seeds) both sides played, with 95% paired-bootstrap intervals.
    ``across_mujoco`` allows A and B of different MuJoCo major versions (to measure what the
    MuJoCo version changes: the same policy on both, say).

    Raises:
        ValueError: the two sides ran different scenes (envs that differ in more than how they
            name the target: :func:`same_scenes`) or object counts, or share fewer than two
            episode seeds.
        MuJoCoVersionError: the two sides ran on different MuJoCo major versions and
            ``across_mujoco`` is false.
    """
    if a.num_objects != b.num_objects or not same_scenes(a.env_id, b.env_id):
        raise ValueError(f"different cells: {a.env_id} with {a.num_objects} objects against {b.env_id} with {b.num_objects}")
    if not across_mujoco:
        try:
            check_one_mujoco({"A": a.mujoco, "B": b.mujoco}, "this paired comparison")
        except MuJoCoVersionError as exc:
            raise MuJoCoVersionError(
                f"{exc} (across_mujoco=True, compare_evals.py --across-mujoco, pairs them anyway)"
            ) from None
    seeds = sorted(set(a.by_seed) & set(b.by_seed))
    if len(seeds) < 2:
        raise ValueError(f"the two sides share {len(seeds)} episode seeds; a paired comparison needs at least 2")
    success = _column(a, b, seeds, "success")
    motions = _column(a, b, seeds, "motions")
    d_success = success[0] - success[1]
    d_motions = motions[0] - motions[1]
    return PairedComparison(
        episodes=len(seeds),
        success_a=float(success[0].mean()),
        success_b=float(success[1].mean()),
        success_difference=float(d_success.mean()),
        success_interval=bootstrap_mean_interval(d_success, seed=seed),
        motions_a=float(motions[0].mean()),
        motions_b=float(motions[1].mean()),
        motions_difference=float(d_motions.mean()),
        motions_interval=bootstrap_mean_interval(d_motions, seed=seed),
        fewer_motions_a=int((d_motions < 0).sum()),
        fewer_motions_b=int((d_motions > 0).sum()),
        primitive_differences=_primitive_differences(a, b, seeds),
        mujoco=(a.mujoco, b.mujoco),
    )


def _primitive_differences(a: EvalRecords, b: EvalRecords, seeds: Sequence[int]) -> dict[str, float]:
    """Mean A minus B count per primitive over ``seeds`` (``{}`` when a record lacks its counts)."""
    counts = [[side.by_seed[s].get("primitives") for s in seeds] for side in (a, b)]
    if any(c is None for side in counts for c in side):
        return {}
    seen = {p for side in counts for c in side if c is not None for p in c}  # (none is None here)
    names = [p for p in PRIMITIVES if p in seen] + sorted(seen - set(PRIMITIVES))
    return {p: float(np.mean([ca.get(p, 0) - cb.get(p, 0) for ca, cb in zip(*counts)])) for p in names}


def _column(a: EvalRecords, b: EvalRecords, seeds: Iterable[int], key: str) -> np.ndarray:
    return np.array([[float(side.by_seed[s][key]) for s in seeds] for side in (a, b)])


def _points(fraction: float) -> str:
    return f"{100 * fraction:+.1f}"


def compare_main(argv: Sequence[str] | None = None) -> int:
    """The command line of ``benchmarks/compare_evals.py``: A minus B, paired, from eval JSON files."""
    parser = argparse.ArgumentParser(
        description="Two policies on the same episodes: paired differences of success and motions."
    )
    parser.add_argument("--a", nargs="+", required=True, help="mpg-eval --json files of policy A")
    parser.add_argument("--b", nargs="+", required=True, help="mpg-eval --json files of policy B")
    parser.add_argument("--names", help="two labels, comma-separated (default: the policies' names)")
    parser.add_argument(
        "--across-mujoco",
        action="store_true",
        help="pair A and B of different MuJoCo major versions (refused otherwise): what the MuJoCo version changes",
    )
    args = parser.parse_args(argv)
    try:
        a, b = load_eval_records(args.a), load_eval_records(args.b)
        names = args.names.split(",") if args.names else [a.policy, b.policy]
        if len(names) != 2:
            raise ValueError(f"--names takes two labels, got {args.names!r}")
        result = compare_paired(a, b, across_mujoco=args.across_mujoco)
    except (ValueError, FileNotFoundError, KeyError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    on = f"MuJoCo {a.mujoco}" if a.mujoco == b.mujoco else f"MuJoCo {a.mujoco} (A) and {b.mujoco} (B)"
    print(f"{a.env_id}, {a.num_objects} objects; A = {names[0]}, B = {names[1]}; {on}")
    print(result.describe(names[0], names[1]))
    return 0
