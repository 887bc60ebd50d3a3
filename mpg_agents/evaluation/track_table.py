"""The track table: one table over several hard tracks, built one cell at a time on disk.

A cell is (track, policy, object count): ``episodes`` episodes on the track's env from
``seed``. :func:`make_track_table` runs each cell that is missing and writes it as soon as it
ends to ``OUT/<track>/cells/<label>_<objects>.json`` (``mpg-eval --json``'s format, with the
policy entry it ran under ``table_policy``), so a stopped run resumes where it stopped and a
small machine can run a table piece by piece (a long cell too, in blocks of seeds). A cell is
used only when it is what the table asks: the track's env, the object count, exactly the seeds
``seed .. seed + episodes - 1``,
the same env options and the same policy entry; anything else raises
:class:`CellMismatchError` naming the file and what differs, never a silently mixed table.

Cells recorded by earlier runs are reused through a TOML file of ``[[cell]]`` entries::

    [[cell]]
    track = "hard"
    label = "Random"          # a label of the policy file
    objects = 30
    evals = "benchmarks/results/hard_track/blocks30/random_*.json"  # mpg-eval --json files, pooled
    # or: table = "benchmarks/results/hard_track/hard_15.json"      # a tables.py report: this label's row

checked the same way: eval files by their env, object count, seeds, env options and the
name the policy gave itself (a built-in's name, or the checkpoint's file name); a report's
row by the report's env, seed, episodes, env options and the policy entry it ran under the
label.

Every cell of a table is of one MuJoCo major version (a cell file from before the version was
recorded reads as 3.x); a run on MuJoCo 4 next to 3.x cells raises
:class:`~mpg_envs.simulation.mujoco_version.MuJoCoVersionError` naming each cell's version.
The report's ``mujoco`` lists the versions its cells record.
"""

from __future__ import annotations

import glob
import json
import tomllib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mpg_agents.evaluation.eval_result import EvalResult
from mpg_agents.evaluation.eval_runner import EvalJob, evaluate_jobs
from mpg_agents.evaluation.evaluate import registered_options
from mpg_agents.evaluation.policy_zoo import BUILTIN
from mpg_agents.evaluation.table_runs import PolicySpec, merged_result
from mpg_agents.evaluation.tables import TRACKS, cell_json, format_markdown, tracks_rows, tracks_success_rows
from mpg_envs.simulation.mujoco_version import recorded_mujoco


class CellMismatchError(ValueError):
    """A recorded cell is not the one the table asks for (another env, object count, seeds,
    env options or policy)."""


def cell_file_name(label: str, objects: int) -> str:
    """``<label>_<objects>.json``, the label's characters other than letters and digits as ``_``."""
    return f"{''.join(c if c.isalnum() else '_' for c in label).strip('_')}_{objects}.json"


@dataclass(frozen=True)
class CellRequest:
    """One cell the table asks for."""

    track: str
    spec: PolicySpec
    objects: int
    episodes: int
    seed: int
    env_options: tuple[tuple[str, Any], ...] = ()  # env keywords beside the track's own

    @property
    def env_id(self) -> str:
        return TRACKS[self.track].env_id

    def policy_entry(self) -> dict[str, Any]:
        """The policy-file entry, as a cell file records it."""
        return {"label": self.spec.label, "policy": self.spec.policy, **dict(self.spec.settings)}

    def recorded_env_options(self) -> dict[str, Any]:
        """The env options an evaluation of this cell records: the track's and the extra ones."""
        return json.loads(json.dumps({**registered_options(self.env_id), **dict(self.env_options)}))

    def check(self, result: EvalResult, source: str) -> None:
        """Raise :class:`CellMismatchError` unless ``result`` is this cell's evaluation (env,
        object count, seeds, env options; the policy is the caller's to check)."""
        seeds = sorted(r.seed for r in result.records)
        problems = []
        if result.env_id != self.env_id or result.num_objects != self.objects:
            problems.append(f"it is {result.env_id} with {result.num_objects} objects, not {self.env_id} with {self.objects}")
        if seeds != list(range(self.seed, self.seed + self.episodes)):
            problems.append(
                f"its seeds are {seeds[0]}..{seeds[-1]} ({len(seeds)} "
                f"episodes), not {self.seed}..{self.seed + self.episodes - 1}"
            )
        if json.loads(json.dumps(result.env_options)) != self.recorded_env_options():
            problems.append(f"its env options are {result.env_options}, not {self.recorded_env_options()}")
        if problems:
            raise CellMismatchError(
                f"{source} is not the cell ({self.track}, {self.spec.label!r}, {self.objects} objects): " + "; ".join(problems)
            )


def _names_policy(name: str, policy: str) -> bool:
    """Whether a recorded evaluation's policy name is ``policy``'s: a built-in's keyword
    (``shipped:<file>`` for the shipped net), else the checkpoint's file name first."""
    if policy in BUILTIN:
        return name == policy or name.startswith(f"{policy}:")
    return name.split(" ")[0] == Path(policy).name


@dataclass(frozen=True)
class ReusedCell:
    """A cell taken from an earlier run: ``evals`` (a glob of ``mpg-eval --json`` files) or
    ``table`` (a ``tables.py`` report holding the label's row)."""

    track: str
    label: str
    objects: int
    evals: str | None = None
    table: str | None = None

    def source(self) -> str:
        return str(self.evals if self.evals is not None else self.table)

    def load(self, request: CellRequest) -> dict[str, Any]:
        """The cell's figures (:func:`~mpg_agents.evaluation.tables.cell_json`), checked against ``request``."""
        if self.evals is not None:
            files = sorted(glob.glob(self.evals))
            if not files:
                raise CellMismatchError(
                    f"reused cell ({self.track}, {self.label!r}, {self.objects}): no file matches {self.evals!r}"
                )
            result = merged_result(files)
            request.check(result, self.evals)
            if not _names_policy(result.policy, request.spec.policy):
                raise CellMismatchError(
                    f"{self.evals} is policy {result.policy!r}, not {request.spec.policy!r} (label {self.label!r})"
                )
            return cell_json(result)
        return self._row(request)

    def _row(self, request: CellRequest) -> dict[str, Any]:
        path = str(self.table)
        report = json.loads(Path(path).read_text())
        entry = {k: v for k, v in request.policy_entry().items() if k != "label"}
        asked = {
            "env": request.env_id,
            "seed": request.seed,
            "episodes": request.episodes,
            "env_options": dict(request.env_options),
        }
        found = {
            "env": report.get("env"),
            "seed": report.get("seed"),
            "episodes": report.get("episodes"),
            "env_options": report.get("env_options"),
        }
        if found != json.loads(json.dumps(asked)):
            raise CellMismatchError(f"{path} ran {found}, the table asks {asked}")
        if report.get("policies", {}).get(self.label) != entry:
            raise CellMismatchError(
                f"{path} ran label {self.label!r} as "
                f"{report.get('policies', {}).get(self.label)}, the policy file says {entry}"
            )
        cell = report.get("rows", {}).get(self.label, {}).get(str(self.objects))
        if cell is None:
            raise CellMismatchError(f"{path} has no cell for {self.label!r} at {self.objects} objects")
        if cell["episodes"] != request.episodes or cell["env_options"] != request.recorded_env_options():
            raise CellMismatchError(
                f"{path}: {self.label!r} at {self.objects} objects ran "
                f"{cell['episodes']} episodes with env options {cell['env_options']}"
            )
        return dict(cell)


def read_reused(path: str | Path) -> dict[tuple[str, str, int], ReusedCell]:
    """The ``[[cell]]`` entries of a reuse file (see the module docstring), keyed (track,
    label, objects). Raises ``ValueError`` naming an entry that is incomplete, names an
    unknown track, gives both or neither of ``evals`` and ``table``, or repeats a cell."""
    try:
        doc = tomllib.loads(Path(path).read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"reuse file {str(path)!r} is not readable TOML: {exc}") from exc
    cells: dict[tuple[str, str, int], ReusedCell] = {}
    for k, entry in enumerate(doc.get("cell", [])):
        where = f"reuse file {str(path)!r}, cell {k}"
        if not isinstance(entry, dict) or not {"track", "label", "objects"} <= set(entry):
            raise ValueError(f"{where}: needs 'track', 'label' and 'objects'")
        if entry["track"] not in TRACKS:
            raise ValueError(f"{where}: unknown track {entry['track']!r}; valid: {', '.join(TRACKS)}")
        if ("evals" in entry) == ("table" in entry):
            raise ValueError(f"{where}: give one of 'evals' (a glob of mpg-eval JSON files) and 'table' (a tables.py report)")
        unknown = set(entry) - {"track", "label", "objects", "evals", "table"}
        if unknown:
            raise ValueError(f"{where}: unknown keys {sorted(unknown)}")
        cell = ReusedCell(
            str(entry["track"]), str(entry["label"]), int(entry["objects"]), entry.get("evals"), entry.get("table")
        )
        key = (cell.track, cell.label, cell.objects)
        if key in cells:
            raise ValueError(f"{where}: {key} is given twice")
        cells[key] = cell
    return cells


def read_cell_file(request: CellRequest, path: Path) -> dict[str, Any]:
    """A cell file this module wrote, checked against ``request`` (policy entry included)."""
    data = json.loads(path.read_text())
    if data.get("table_policy") != request.policy_entry():
        raise CellMismatchError(
            f"{path} ran policy entry {data.get('table_policy')}, the policy file now says {request.policy_entry()}: "
            "delete the file to run the cell again, or restore the entry"
        )
    result = merged_result([path])
    request.check(result, str(path))
    return cell_json(result)


def write_cell_file(request: CellRequest, result: EvalResult, path: Path) -> None:
    """``result`` as ``mpg-eval --json`` writes it, with the policy entry it ran."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".json.part")
    tmp.write_text(json.dumps({**result.to_dict(), "table_policy": request.policy_entry()}))
    tmp.replace(path)  # a stopped run leaves no half-written cell


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
        request.spec.policy, request.env_id, episodes, seed, request.objects, request.spec.settings, request.env_options
    )
    (result,), timing = evaluate_jobs([job], workers, ray_address, on_record=on_record, backend=backend)
    return result, timing.wall_seconds


def block_folder(path: Path) -> Path:
    """Where a cell run in blocks keeps its finished blocks: ``<cell>.blocks/<first seed>.json``."""
    return path.with_name(path.stem + ".blocks")


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
        elif json.loads(block.read_text()).get("table_policy") != request.policy_entry():
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
        if name not in TRACKS or not TRACKS[name].strict_columns:
            raise ValueError(
                f"unknown or non-strict track {name!r}; valid: {[t for t, s in TRACKS.items() if s.strict_columns]}"
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
        "tracks": {name: TRACKS[name].env_id for name in tracks},
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
    if cells:
        markdown += f"\n\nMeasured on MuJoCo {', '.join(mujoco_versions)}."
    if missing:
        counts = {name: sum(1 for m in missing if m[0] == name) for name in tracks}
        markdown += (
            "\n\nNot run yet: "
            + "; ".join(
                f"{TRACKS[name].scenes} ({TRACKS[name].env_id}), {k} of {len(specs) * len(objects)} cells"
                for name, k in counts.items()
                if k
            )
            + "."
        )
    return report, markdown
