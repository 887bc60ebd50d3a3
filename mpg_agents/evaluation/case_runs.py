"""A policy on every case of a case set (:mod:`mpg_envs.scenes.cases`), N runs per case.

Run ``r`` of case ``c`` (0-based, in the set's order) loads the case's scene jittered for
run ``r`` (:func:`mpg_envs.scenes.cases.jitter_scene`; run 0 is the case as written) and is episode
``r`` of :func:`mpg_agents.evaluation.evaluate.run_episode` with seed ``seed + CASE_SEED_STRIDE * c``:
its reset, the policy and the action space are seeded ``seed + CASE_SEED_STRIDE * c + r``,
so every run is reproducible on its own. Runs use strict retrieval by default (the env's
``wrong_grasp="fail"``: a grasp that lifts another object ends the run as a failure).

Each case gives one :class:`CaseRow`: successes out of runs, mean motions, mis-picks
(grasps that lifted another object) per run, the grasp success rate (target grasps /
grasp attempts) and the target's mean visible fraction at reset;
:attr:`CaseRunResult.overall` pools every run of the set.

Every case's scene is read and checked before any run (:func:`check_case_set`: parsed, placed,
no interpenetration, a target where the env needs one), and one error names every bad file. A
run that raises all the same is kept as a failure (:mod:`mpg_agents.evaluation.failures`) and
the other runs go on; :func:`without_output` keeps a run's own result file, written into the
cases' folder, from being read back as a case.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import gymnasium as gym

from mpg_agents.evaluation.eval_result import EpisodeRecord
from mpg_agents.evaluation.evaluate import env_id_of, run_episode
from mpg_agents.evaluation.failures import EpisodeFailure, NothingFinished, describe_failures, failures_line
from mpg_agents.evaluation.policy_zoo import make_policy
from mpg_envs._version import __version__
from mpg_envs.scenes.cases import Case, CaseSet, jitter_scene
from mpg_envs.scenes.scene_file import SceneFile, SceneFileError
from mpg_envs.scenes.scene_io import SCENE_FORMAT
from mpg_envs.scenes.scene_loading import place_scene
from mpg_envs.simulation.mujoco_version import running_mujoco

CASE_SEED_STRIDE = 1000
"""Case ``c``'s runs are seeded from ``seed + CASE_SEED_STRIDE * c``; at most this many runs."""

STRICT = {"wrong_grasp": "fail"}
"""The env settings case runs use unless told otherwise: strict retrieval."""


@dataclass(frozen=True)
class CaseRow:
    """What a policy did on one case (or, for the overall row, on every case)."""

    case: str
    runs: int
    successes: int
    mean_motions: float  # failures count all their motions
    mis_picks: float  # grasps that lifted another object, per run
    grasp_attempts: int
    target_grasps: int
    grasp_success_rate: float | None  # target grasps / grasp attempts
    end_reasons: dict[str, int]
    note: str = ""
    visible_fraction: float | None = None  # the target's mean visible fraction at reset

    @classmethod
    def of(cls, case: str, records: Sequence[EpisodeRecord], note: str = "") -> CaseRow:
        """The row of ``records`` (at least one)."""
        if not records:
            raise ValueError(f"case {case!r}: no runs to summarise")
        grasps = sum(r.grasp_attempts for r in records)
        target = sum(r.target_grasps for r in records)
        visible = [r.visible_fraction for r in records if r.visible_fraction is not None]
        reasons: dict[str, int] = {}
        for r in records:
            reasons[r.end_reason] = reasons.get(r.end_reason, 0) + 1
        return cls(
            case=case,
            runs=len(records),
            successes=sum(r.success for r in records),
            mean_motions=sum(r.motions for r in records) / len(records),
            mis_picks=sum(r.wrong_grasps for r in records) / len(records),
            grasp_attempts=grasps,
            target_grasps=target,
            grasp_success_rate=target / grasps if grasps else None,
            end_reasons=dict(sorted(reasons.items())),
            note=note,
            visible_fraction=sum(visible) / len(visible) if visible else None,
        )

    def cells(self) -> list[str]:
        """The row's table cells: case, visible fraction, successes, mean motions, mis-picks per
        run, grasp success."""
        gsr = (
            "n/a"
            if self.grasp_success_rate is None
            else f"{100 * self.grasp_success_rate:.0f}% ({self.target_grasps}/{self.grasp_attempts})"
        )
        visible = "n/a" if self.visible_fraction is None else f"{self.visible_fraction:.2f}"
        return [self.case, visible, f"{self.successes}/{self.runs}", f"{self.mean_motions:.2f}", f"{self.mis_picks:.2f}", gsr]


HEADER = ["case", "visible", "success", "motions", "mis-picks/run", "grasp success"]
"""Column names of :meth:`CaseRow.cells`."""


@dataclass
class CaseRunResult:
    """Every case's row, the overall row and the runs' records."""

    policy: str
    case_set: str
    env_id: str
    env_kwargs: dict[str, Any]  # the env settings the runs used (gym.make keywords)
    runs: int
    seed: int
    rows: list[CaseRow]
    overall: CaseRow
    records: dict[str, list[EpisodeRecord]]
    wall_seconds: float = field(default=0.0, compare=False)
    failures: list[EpisodeFailure] = field(default_factory=list)  # runs that raised (left out of the rows)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready data (wall time left out, so one seed gives one file)."""
        return {
            "package_version": __version__,
            "mujoco_version": running_mujoco(),
            "policy": self.policy,
            "case_set": self.case_set,
            "env_id": self.env_id,
            "env_kwargs": dict(self.env_kwargs),
            "runs": self.runs,
            "seed": self.seed,
            "rows": [asdict(row) for row in self.rows],
            "overall": asdict(self.overall),
            "records": {case: [r.to_dict() for r in records] for case, records in self.records.items()},
            "failures": [f.to_dict() for f in self.failures],
        }

    def table(self) -> str:
        """Aligned plain text: one line per case and the overall line."""
        lines = [HEADER] + [row.cells() for row in self.rows] + [self.overall.cells()]
        widths = [max(len(line[k]) for line in lines) for k in range(len(HEADER))]
        failed = [f"failed: {describe_failures(self.failures)}"] if self.failures else []
        return "\n".join(["  ".join(cell.ljust(w) for cell, w in zip(line, widths)).rstrip() for line in lines] + failed)

    def failures_line(self) -> str:
        """One line naming the runs that failed and why (``""`` when none did)."""
        return failures_line(self.failures, self.overall.runs, "case runs")

    def markdown(self) -> str:
        """A Markdown table: one row per case and the overall row (in bold)."""
        rows = [row.cells() for row in self.rows] + [[f"**{c}**" for c in self.overall.cells()]]
        lines = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
        return "\n".join(lines + ["| " + " | ".join(cells) + " |" for cells in rows])


def run_cases(
    policy,
    env: gym.Env,
    case_set: CaseSet,
    runs: int = 1,
    seed: int = 0,
    on_record: Callable[[Case, EpisodeRecord], None] | None = None,
) -> CaseRunResult:
    """Run ``policy`` on ``env`` for ``runs`` runs of every case of ``case_set`` (see the module docstring).

    Raises:
        SceneFileError: before any run, naming every case whose scene cannot be loaded (:func:`check_case_set`).
        NothingFinished: every run raised (the message lists why).
    """
    if isinstance(runs, bool) or not isinstance(runs, int) or not 1 <= runs <= CASE_SEED_STRIDE:
        raise ValueError(f"runs must be an integer in 1..{CASE_SEED_STRIDE}, got {runs!r}")
    if not len(case_set):
        raise ValueError(f"case set {case_set.name!r} has no cases")
    start = time.perf_counter()
    unwrapped: Any = env.unwrapped  # the MPG env (gym.Env does not declare its attributes)
    scenes = check_case_set(case_set, env)
    rows, records, failures = [], {}, []
    for c, case in enumerate(case_set):
        done = []
        for r in range(runs):
            options = {"scene": jitter_scene(scenes[c], r, case.name, unwrapped.config.workspace)}
            try:
                record = run_episode(policy, env, r, seed + CASE_SEED_STRIDE * c, reset_options=options)
            except Exception as exc:  # kept as a failure: the other runs go on
                failures.append(EpisodeFailure.of(exc, r, seed + CASE_SEED_STRIDE * c + r, case.name))
                continue
            done.append(record)
            if on_record is not None:
                on_record(case, record)
        if done:
            records[case.name] = done
            rows.append(CaseRow.of(case.name, done, case.note))
    if not rows:
        raise NothingFinished(f"all {len(failures)} case runs failed: {describe_failures(failures)}")
    overall = CaseRow.of("overall", [r for done in records.values() for r in done])
    return CaseRunResult(
        policy=getattr(policy, "name", type(policy).__name__),
        case_set=case_set.name,
        env_id=env_id_of(env),
        env_kwargs={"wrong_grasp": unwrapped.wrong_grasp},
        runs=runs,
        seed=seed,
        rows=rows,
        overall=overall,
        records=records,
        wall_seconds=time.perf_counter() - start,
        failures=failures,
    )


def check_case_set(case_set: CaseSet, env: gym.Env) -> list[SceneFile]:
    """Every case's scene, read and placed in ``env``'s simulation (no episode runs: the env
    must be reset before its next step), in the set's order.

    Raises:
        SceneFileError: one line naming every case whose scene cannot be read or placed (a
            missing or malformed file, objects interpenetrating or sunk into the table, no
            target where ``env`` needs one), with what is wrong with each.
    """
    unwrapped: Any = env.unwrapped  # the MPG env (gym.Env does not declare its attributes)
    workspace, needs_target = unwrapped.config.workspace, not unwrapped.stage.mask_all_objects
    scenes, bad = [], []
    for case in case_set:
        try:
            scene = case.scene_file(workspace, unwrapped.config.object_set_seed)
            place_scene(unwrapped.sim.build, scene, workspace, drop_outside=False)
            if needs_target and scene.target is None:
                raise SceneFileError(f"scene {scene.source!r} has no target; {env_id_of(env)} needs one")
        except (ValueError, OSError) as exc:
            bad.append(f"case {case.name!r}: {exc}")
            continue
        scenes.append(scene)
    if bad:
        raise SceneFileError(
            f"case set {case_set.name!r}: {len(bad)} of {len(case_set)} cases cannot be loaded, "
            f"nothing was run: {'; '.join(bad)}"
        )
    return scenes


def without_output(case_set: CaseSet, output: str | Path | None) -> CaseSet:
    """``case_set`` less the case read from ``output``, the run's own result file, when it
    lies among the cases' files (a result written into the cases' folder by an earlier run is
    not a case).

    Raises:
        ValueError: ``output`` is a scene file of the set (the run would overwrite it).
    """
    if output is None or not Path(output).exists():
        return case_set
    out = Path(output).resolve()
    same = [c for c in case_set if not isinstance(c.scene, SceneFile) and Path(c.scene).resolve() == out]
    if same and _is_scene_file(out):
        raise ValueError(
            f"{str(output)!r} is the scene file of case {same[0].name!r}: the result would overwrite it; "
            "write the result to another file"
        )
    return replace(case_set, cases=tuple(c for c in case_set if c not in same)) if same else case_set


def _is_scene_file(path: Path) -> bool:
    """A plain-text scene file (``.txt``) or a JSON file of the scene format."""
    if path.suffix.lower() == ".txt":
        return True
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and doc.get("format") == SCENE_FORMAT


def run_case_set(
    policy_name: str,
    case_set: CaseSet,
    runs: int = 1,
    seed: int = 0,
    env_id: str = "MPG-Occluded-v0",
    env_kwargs: dict[str, Any] | None = None,
    policy_kwargs: dict[str, Any] | None = None,
    on_record: Callable[[Case, EpisodeRecord], None] | None = None,
) -> CaseRunResult:
    """:func:`run_cases` with a fresh ``gym.make(env_id)`` (strict retrieval, :data:`STRICT`,
    unless ``env_kwargs`` says otherwise) and :func:`mpg_agents.evaluation.policy_zoo.make_policy`'s
    ``policy_name``."""
    settings = {**STRICT, **(env_kwargs or {})}
    env = gym.make(env_id, **settings)
    try:
        policy = make_policy(policy_name, env, seed=seed, **(policy_kwargs or {}))
        result = run_cases(policy, env, case_set, runs, seed, on_record)
    finally:
        env.close()
    result.env_kwargs = settings
    return result
