"""The track table: one table over several hard tracks, built one cell at a time on disk.

A cell is (track, policy, object count): ``episodes`` episodes on the track's env from
``seed`` (:class:`~mpg_agents.evaluation.track_cells.CellRequest`). :func:`make_track_table` runs
each cell that is missing and writes it as soon as it ends to
``OUT/<track>/cells/<label>_<objects>.json`` (``mpg-eval --json``'s format, with the policy entry
it ran under ``table_policy``), so a stopped run resumes where it stopped and a small machine can
run a table piece by piece (a long cell too, in blocks of seeds). A cell is used only when it is
what the table asks: the track's env, the object count, exactly the seeds
``seed .. seed + episodes - 1``, the same env options and the same policy entry; anything else
raises :class:`~mpg_agents.evaluation.track_cells.CellMismatchError` naming the file and what
differs, never a silently mixed table. Cells recorded by earlier runs are reused through a TOML
file of ``[[cell]]`` entries, checked the same way (:mod:`mpg_agents.evaluation.reused_cells`).

Every cell of a table is of one MuJoCo major version (a cell file from before the version was
recorded reads as 3.x); a run on MuJoCo 4 next to 3.x cells raises
:class:`~mpg_envs.simulation.mujoco_version.MuJoCoVersionError` naming each cell's version.
The report's ``mujoco`` lists the versions its cells record.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from mpg_agents.evaluation.eval_result import EvalResult
from mpg_agents.evaluation.eval_runner import EvalJob, evaluate_jobs
from mpg_agents.evaluation.finding_table import finding_rows
from mpg_agents.evaluation.reused_cells import ReusedCell
from mpg_agents.evaluation.table_runs import PolicySpec, merged_result
from mpg_agents.evaluation.tables import TABLE_TRACKS, cell_json, format_markdown, tracks_rows, tracks_success_rows
from mpg_agents.evaluation.track_cells import (
    CellMismatchError,
    CellRequest,
    block_folder,
    cell_file_name,
    compared_entry,
    read_cell_file,
    write_cell_file,
)
from mpg_envs.simulation.mujoco_version import recorded_mujoco


def _cell(
    request: CellRequest,
    path: Path,
    reused: ReusedCell | None,
    run: Callable[[CellRequest], bool] | None,
    workers: int | None,
    ray_address: str | None,
    backend: str,
    on_record: Callable[[EvalJob, Any], None] | None,
    block_episodes: int | None = None,
) -> tuple[dict[str, Any], str, str, float] | None:
    """(cell, source, how, wall seconds) of one cell: reused, read from ``path``, or run (in
    blocks of ``block_episodes`` seeds when given) and written there; ``None`` when it is none
    of these."""
    if reused is not None:
        return reused.load(request), reused.source(), "reused", 0.0
    if path.is_file():
        return read_cell_file(request, path), str(path), "recorded", 0.0
    if run is None or not run(request):
        return None
    if block_episodes and block_episodes < request.episodes:
        result, seconds = _run_in_blocks(request, path, block_episodes, workers, ray_address, backend, on_record)
    else:
        result, seconds = _run_seeds(request, request.seed, request.episodes, workers, ray_address, backend, on_record)
    write_cell_file(request, result, path)
    return cell_json(result), str(path), "ran", seconds


def _run_seeds(
    request: CellRequest,
    seed: int,
    episodes: int,
    workers: int | None,
    ray_address: str | None,
    backend: str,
    on_record: Callable[[EvalJob, Any], None] | None,
) -> tuple[EvalResult, float]:
    """The cell's policy and env on ``episodes`` seeds from ``seed``: the result and its wall seconds."""
    job = EvalJob(
        request.spec.policy, request.env_id, episodes, seed, request.objects, request.spec.settings, request.all_env_options
    )
    (result,), timing = evaluate_jobs([job], workers, ray_address, on_record=on_record, backend=backend)
    return result, timing.wall_seconds


def _run_in_blocks(
    request: CellRequest,
    path: Path,
    block_episodes: int,
    workers: int | None,
    ray_address: str | None,
    backend: str,
    on_record: Callable[[EvalJob, Any], None] | None,
) -> tuple[EvalResult, float]:
    """The cell as blocks of ``block_episodes`` seeds, one after another (each over the
    workers), every block written as it ends, so a stopped cell loses at most one block; blocks
    already on disk are checked and kept. Returns the pooled cell and the blocks' wall seconds."""
    folder, files, seconds = block_folder(path), [], 0.0
    for start in range(0, request.episodes, block_episodes):
        block = folder / f"{request.seed + start}.json"
        if not block.is_file():
            n = min(block_episodes, request.episodes - start)
            result, wall = _run_seeds(request, request.seed + start, n, workers, ray_address, backend, on_record)
            write_cell_file(request, result, block)
            seconds += wall
        elif compared_entry(json.loads(block.read_text()).get("table_policy")) != compared_entry(request.policy_entry()):
            raise CellMismatchError(
                f"{block} ran another policy entry than {request.policy_entry()}: delete {folder} to run the cell again"
            )
        files.append(block)
    result = merged_result(files)
    request.check(result, str(folder))
    return result, seconds


def make_track_table(
    tracks: Sequence[str],
    specs: Sequence[PolicySpec],
    objects: Sequence[int],
    episodes: int,
    seed: int,
    out: str | Path,
    reused: Mapping[tuple[str, str, int], ReusedCell] | None = None,
    env_options: Mapping[str, Any] | None = None,
    run: Callable[[CellRequest], bool] | None = None,
    workers: int | None = 1,
    ray_address: str | None = None,
    backend: str = "ray",
    on_cell: Callable[[CellRequest, str, float], None] | None = None,
    on_record: Callable[[EvalJob, Any], None] | None = None,
    block_episodes: int | None = None,
) -> tuple[dict[str, Any], str]:
    """The table of ``tracks`` x ``specs`` x ``objects``: every cell reused (``reused``),
    read from ``OUT/<track>/cells/``, or run there when ``run(request)`` says so; a cell
    neither recorded nor run is absent from the table. Reused cells must carry labels of
    ``specs`` (``ValueError`` otherwise). Returns the report (``rows``:
    ``{track: {label: {objects: cell}}}``, each cell's
    ``source``, the cells ``missing``) and the Markdown: the success grid
    (:func:`~mpg_agents.evaluation.tables.tracks_success_rows`), then every figure
    (:func:`~mpg_agents.evaluation.tables.tracks_rows`). ``on_cell(request, how,
    seconds)`` hears of each cell: ``how`` is ``reused``, ``recorded`` or ``ran``;
    ``on_record(job, record)`` of each episode run. With ``block_episodes``, a cell runs as
    blocks of that many seeds, each kept as it ends (``<cell>.blocks/``; a stopped cell resumes
    at its first missing block), then pooled into the cell file: for cells that take longer
    than a sitting."""
    if block_episodes is not None and (
        isinstance(block_episodes, bool) or not isinstance(block_episodes, int) or block_episodes < 1
    ):
        raise ValueError(f"block_episodes must be a positive integer or None, got {block_episodes!r}")
    labels = [s.label for s in specs]
    if len(set(labels)) != len(labels):
        raise ValueError(f"policy labels must differ, got {labels}")
    for name in tracks:
        if name not in TABLE_TRACKS or not TABLE_TRACKS[name].strict_columns:
            raise ValueError(
                f"unknown or non-strict track {name!r}; valid: {[t for t, s in TABLE_TRACKS.items() if s.strict_columns]}"
            )
    reused = dict(reused or {})
    strangers = sorted({label for _, label, _ in reused} - set(labels))
    if strangers:
        raise ValueError(f"reused cells of labels the policy file does not have: {strangers}; its labels: {labels}")
    extra = tuple(sorted((env_options or {}).items()))
    cells: dict[tuple[str, str, int], dict[str, Any]] = {}
    sources: dict[str, dict[str, dict[str, str]]] = {}
    missing = []
    for name in tracks:
        for spec in specs:
            for n in objects:
                request = CellRequest(name, spec, n, episodes, seed, extra)
                path = Path(out) / name / "cells" / cell_file_name(spec.label, n)
                found = _cell(
                    request,
                    path,
                    reused.get((name, spec.label, n)),
                    run,
                    workers,
                    ray_address,
                    backend,
                    on_record,
                    block_episodes,
                )
                if found is None:
                    missing.append([name, spec.label, n])
                    continue
                cells[(name, spec.label, n)], source, how, seconds = found
                sources.setdefault(name, {}).setdefault(spec.label, {})[str(n)] = source
                if on_cell is not None:
                    on_cell(request, how, seconds)
    header, body = tracks_rows(tracks, labels, objects, cells)
    rows: dict[str, dict[str, dict[str, Any]]] = {}
    for (name, label, n), cell in cells.items():
        rows.setdefault(name, {}).setdefault(label, {})[str(n)] = cell
    mujoco_versions = sorted({recorded_mujoco(cell.get("versions")) for cell in cells.values()})
    report = {
        "tracks": {name: TABLE_TRACKS[name].env_id for name in tracks},
        "objects": list(objects),
        "episodes": episodes,
        "seed": seed,
        "env_options": dict(env_options or {}),
        "policies": {s.label: {"policy": s.policy, **dict(s.settings)} for s in specs},
        "rows": rows,
        "sources": sources,
        "missing": missing,
        "mujoco": mujoco_versions,
    }
    grid_header, grid_body = tracks_success_rows(tracks, labels, objects, cells)
    markdown = "\n\n".join(
        [
            "Success [95% interval] in mean motions:",
            format_markdown(grid_header, grid_body),
            "Every figure:",
            format_markdown(header, body, text_columns=2),
        ]
    )
    finding_header, finding_body = finding_rows(tracks, labels, objects, cells)
    if finding_body:
        markdown += "\n\nFinding the target:\n\n" + format_markdown(finding_header, finding_body, text_columns=3)
    if cells:
        markdown += f"\n\nMeasured on MuJoCo {', '.join(mujoco_versions)}."
    if missing:
        counts = {name: sum(1 for m in missing if m[0] == name) for name in tracks}
        markdown += (
            "\n\nNot run yet: "
            + "; ".join(
                f"{TABLE_TRACKS[name].scenes} ({TABLE_TRACKS[name].env_id}), {k} of {len(specs) * len(objects)} cells"
                for name, k in counts.items()
                if k
            )
            + "."
        )
    return report, markdown
