"""Run a results table: every (policy, object count) cell of a track on the same seeds.

Every cell runs ``episodes`` episodes (episode ``i`` reset with seed ``seed + i``, so every
policy meets the same scenes at a given object count) as Ray tasks or on a local process
pool (:mod:`mpg_agents.evaluation.eval_runner`); results are identical for any number of workers. The
policies are named (``oracle``, ``shipped``, a checkpoint path) or listed in a TOML file
with a label and the settings each runs with::

    [[policy]]
    label = "Grasping-Only (learned, finger mask)"
    policy = "benchmarks/results/grasp_only_occluded/at3300/weights.safetensors"
    grasp_fingers = "clear"       # any further key is a make_policy keyword

:func:`run_table` returns the report (the cells as data, timings) that ``benchmarks/tables.py``
prints and writes; :func:`table_from_evals` makes the same table from ``mpg-eval --json`` files
run apart (seed blocks run one after another on a small machine, say).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mpg_agents.evaluation.comparison import load_eval_records
from mpg_agents.evaluation.eval_result import EpisodeRecord, EvalResult
from mpg_agents.evaluation.eval_runner import EvalJob, evaluate_jobs
from mpg_agents.evaluation.evaluate import summarise
from mpg_agents.evaluation.motion_log import MotionRecord
from mpg_agents.evaluation.tables import TABLE_TRACKS, format_markdown, format_text, paper_json, rows_json, table_rows
from mpg_envs.settings_fields import read_settings_file
from mpg_envs.simulation.mujoco_version import MUJOCO_KEY


@dataclass(frozen=True)
class PolicySpec:
    """A policy of a table: its row label, what :func:`~mpg_agents.evaluation.policy_zoo.make_policy`
    builds, and the keywords it is built with."""

    label: str
    policy: str
    settings: tuple[tuple[str, Any], ...] = field(default=())


def read_policy_specs(path: str | Path) -> list[PolicySpec]:
    """The ``[[policy]]`` entries of a TOML file (see the module docstring); relative
    checkpoint paths are read from the current directory. Raises ``ValueError`` naming the
    entry that lacks ``label`` or ``policy``."""
    path = Path(path)
    doc = read_settings_file(path, "policy file", "TOML")
    specs = []
    for k, entry in enumerate(doc.get("policy", [])):
        if not isinstance(entry, dict) or "label" not in entry or "policy" not in entry:
            raise ValueError(f"policy file {str(path)!r}: entry {k} needs 'label' and 'policy'")
        settings = tuple(sorted((key, value) for key, value in entry.items() if key not in ("label", "policy")))
        specs.append(PolicySpec(str(entry["label"]), str(entry["policy"]), settings))
    if not specs:
        raise ValueError(f"policy file {str(path)!r} lists no [[policy]]")
    return specs


def run_table(
    track: str,
    policies: Sequence[PolicySpec],
    objects: Sequence[int],
    episodes: int,
    seed: int,
    workers: int | None,
    ray_address: str | None = None,
    backend: str = "ray",
    env_options: Mapping[str, Any] | None = None,
    on_record: Callable[[EvalJob, Any], None] | None = None,
) -> tuple[dict[str, Any], str, str]:
    """Every cell of ``track`` for ``policies`` at ``objects``: the report as data (``cells``
    holds each cell's full evaluation, ``mpg-eval --json``'s format, keyed ``"label|objects"``),
    the table as text and as Markdown."""
    if track not in TABLE_TRACKS:
        raise ValueError(f"unknown track {track!r}; valid: {', '.join(TABLE_TRACKS)}")
    labels = [p.label for p in policies]
    if len(set(labels)) != len(labels):
        raise ValueError(f"policy labels must differ, got {labels}")
    spec = TABLE_TRACKS[track]
    env_kwargs = tuple(sorted((env_options or {}).items()))
    cells = [(p, n) for p in policies for n in objects]
    jobs = [EvalJob(p.policy, spec.env_id, episodes, seed, n, p.settings, env_kwargs) for p, n in cells]
    results, timing = evaluate_jobs(jobs, workers, ray_address, on_record=on_record, backend=backend)
    by_cell = {(p.label, n): r for (p, n), r in zip(cells, results)}
    header, body, paper_rows = table_rows(labels, objects, by_cell, spec, {label: label for label in labels})
    report = {
        "track": track,
        "env": spec.env_id,
        "env_options": dict(env_options or {}),
        "episodes": episodes,
        "objects": list(objects),
        "seed": seed,
        "policies": {p.label: {"policy": p.policy, **dict(p.settings)} for p in policies},
        "rows": rows_json(by_cell),
        "paper": paper_json(objects) if spec.paper_rows else {},
        "workers": timing.workers,
        "wall_seconds": round(timing.wall_seconds, 2),
        "startup_seconds": round(timing.startup_seconds, 2),
        "task_seconds": round(timing.task_seconds, 2),
        "parallelism": round(timing.parallelism, 3),
    }
    report["cells"] = {f"{label}|{n}": result.to_dict() for (label, n), result in by_cell.items()}
    return report, format_text(header, body, paper_rows), format_markdown(header, body)


def merged_result(paths: Sequence[str | Path]) -> EvalResult:
    """One cell from ``mpg-eval --json`` files of the same policy and cell run in seed blocks
    (:func:`mpg_agents.evaluation.comparison.load_eval_records`): their episodes in seed order, summarised
    as one evaluation (the first seed is the cell's). Its ``versions`` are the files' (the first
    file's package version, their one MuJoCo version: ``"3.x"`` for files that record none),
    not this process's."""
    cell = load_eval_records(paths)
    first = json.loads(Path(paths[0]).read_text())
    fields = {f.name for f in dataclasses.fields(EpisodeRecord)} - {"index", "seconds"}
    records = []
    for index, seed in enumerate(sorted(cell.by_seed)):
        data = {k: v for k, v in cell.by_seed[seed].items() if k in fields}
        data["actions"] = tuple(tuple(a) if isinstance(a, list) else a for a in data.get("actions", ()))
        data["steps"] = tuple(MotionRecord.from_dict(m) for m in data.get("steps", ()))
        records.append(EpisodeRecord(index=index, **data))
    result = summarise(
        records,
        first["policy"],
        cell.env_id,
        int(cell.num_objects or 0),
        min(cell.by_seed),
        0.0,
        env_options=first.get("env_options", {}),
    )
    return dataclasses.replace(result, versions={**first.get("versions", {}), MUJOCO_KEY: cell.mujoco})


def table_from_evals(track: str, cells: Mapping[str, Sequence[str | Path]], objects: int) -> tuple[dict[str, Any], str, str]:
    """A table of ``track`` at ``objects`` objects from recorded evaluations: ``cells`` maps a
    row label to the ``mpg-eval --json`` files of its seed blocks. Returns the report, the text
    and the Markdown table, as :func:`run_table` does."""
    spec = TABLE_TRACKS[track]
    results = {(label, objects): merged_result(paths) for label, paths in cells.items()}
    for (label, _), result in results.items():
        if result.env_id != spec.env_id or result.num_objects != objects:
            raise ValueError(
                f"{label}: its files are {result.env_id} with {result.num_objects} objects, not {spec.env_id} with {objects}"
            )
    labels = list(cells)
    header, body, paper_rows = table_rows(labels, [objects], results, spec, {label: label for label in labels})
    report = {
        "track": track,
        "env": spec.env_id,
        "objects": [objects],
        "episodes": {label: results[(label, objects)].episodes for label in labels},
        "sources": {label: [str(p) for p in paths] for label, paths in cells.items()},
        "rows": rows_json(results),
    }
    return report, format_text(header, body, paper_rows), format_markdown(header, body)
