"""Track-table cells reused from earlier runs, named in a TOML file of ``[[cell]]`` entries::

    [[cell]]
    track = "hard"
    label = "Random"          # a label of the policy file
    objects = 30
    evals = "benchmarks/results/hard_track/blocks30/random_*.json"  # mpg-eval --json files, pooled
    # or: table = "benchmarks/results/hard_track/hard_15.json"      # a tables.py report: this label's row
    # scenes_of = "hard"      # optional: the files are this track's cell (see below)

checked as a cell file is (:class:`~mpg_agents.evaluation.track_cells.CellRequest`): eval files by
their env, object count, seeds, env options and the name the policy gave itself (a built-in's
name, or the checkpoint's file name), another track table's cell files by the policy entry they
ran; a report's row by the report's env, seed, episodes, env options and the policy entry it ran
under the label. Anything else raises
:class:`~mpg_agents.evaluation.track_cells.CellMismatchError`.

``scenes_of`` reuses another track's cell for a track that differs from it only in how the
target is named (``target_spec``: the hard track and its visible and exemplar versions play the
same scenes step for step, the exemplar's recoloured), and only for a scripted baseline whose
actions do not depend on that (:attr:`~mpg_envs.policies.registry.ScriptedBaseline.reads_target_spec` false: the
oracle, random), so the two cells are the same episodes; the files are checked as that
track's cell. Any other track or policy raises
:class:`~mpg_agents.evaluation.track_cells.CellMismatchError`.
"""

from __future__ import annotations

import dataclasses
import glob
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mpg_agents.evaluation.comparison import same_scenes
from mpg_agents.evaluation.policy_zoo import is_builtin
from mpg_agents.evaluation.table_runs import merged_result
from mpg_agents.evaluation.tables import TABLE_TRACKS, cell_json
from mpg_agents.evaluation.track_cells import CellMismatchError, CellRequest, compared_entry
from mpg_envs.policies.registry import SCRIPTED_BASELINES, baseline_name
from mpg_envs.settings_fields import read_settings_file


def _names_policy(name: str, policy: str) -> bool:
    """Whether a recorded evaluation's policy name is ``policy``'s: a built-in's keyword
    (``shipped:<file>`` for the shipped net; a scripted baseline's former name is its name), else
    the checkpoint's file name first."""
    if is_builtin(policy):
        keyword = name.split(":")[0]
        return (baseline_name(keyword) or keyword) == (baseline_name(policy) or policy)
    return name.split(" ")[0] == Path(policy).name


def _ran_policy(files: list[str], name: str, request: CellRequest) -> bool:
    """Whether recorded files ran ``request``'s policy: a track table's cell files by the policy
    entry they ran (its label aside), other evaluations by their policy's name."""
    entries = [json.loads(Path(f).read_text()).get("table_policy") for f in files]
    if all(entry is not None for entry in entries):
        asked = compared_entry({k: v for k, v in request.policy_entry().items() if k != "label"})
        return all(compared_entry({k: v for k, v in entry.items() if k != "label"}) == asked for entry in entries)
    return _names_policy(name, request.spec.policy)


@dataclass(frozen=True)
class ReusedCell:
    """A cell taken from an earlier run: ``evals`` (a glob of ``mpg-eval --json`` files) or
    ``table`` (a ``tables.py`` report holding the label's row), of ``scenes_of``'s track when
    given (see the module docstring)."""

    track: str
    label: str
    objects: int
    evals: str | None = None
    table: str | None = None
    scenes_of: str | None = None

    def source(self) -> str:
        where = str(self.evals if self.evals is not None else self.table)
        return where if self.scenes_of is None else f"{where} (the {self.scenes_of} track's episodes)"

    def load(self, request: CellRequest) -> dict[str, Any]:
        """The cell's figures (:func:`~mpg_agents.evaluation.tables.cell_json`), checked against ``request``."""
        if self.scenes_of is not None:
            request = self._twin(request)
        if self.evals is not None:
            files = sorted(glob.glob(self.evals))
            if not files:
                raise CellMismatchError(
                    f"reused cell ({self.track}, {self.label!r}, {self.objects}): no file matches {self.evals!r}"
                )
            result = merged_result(files)
            request.check(result, self.evals)
            if not _ran_policy(files, result.policy, request):
                raise CellMismatchError(
                    f"{self.evals} is policy {result.policy!r}, not {request.spec.policy!r} (label {self.label!r})"
                )
            return cell_json(result)
        return self._row(request)

    def _twin(self, request: CellRequest) -> CellRequest:
        """``request`` on the ``scenes_of`` track, when that track plays the same episodes for
        the request's policy; else :class:`CellMismatchError` saying why not."""
        twin = dataclasses.replace(request, track=str(self.scenes_of))
        where = f"reused cell ({self.track}, {self.label!r}, {self.objects}) from the {self.scenes_of} track"
        if not same_scenes(request.env_id, twin.env_id, dict(request.all_env_options), dict(twin.all_env_options)):
            raise CellMismatchError(f"{where}: the two tracks differ in more than how they name the target")
        baseline = SCRIPTED_BASELINES.get(baseline_name(request.spec.policy) or "")
        if baseline is None or baseline.reads_target_spec or request.spec.settings:
            raise CellMismatchError(
                f"{where}: policy {request.spec.policy!r} may act on how the target is named; only a scripted "
                "baseline that does not (reads_target_spec false: "
                f"{', '.join(n for n, b in SCRIPTED_BASELINES.items() if not b.reads_target_spec)}), without settings, "
                "plays the same episodes on both"
            )
        return twin

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
        if compared_entry(report.get("policies", {}).get(self.label)) != compared_entry(entry):
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
    doc = read_settings_file(path, "reuse file", "TOML")
    cells: dict[tuple[str, str, int], ReusedCell] = {}
    for k, entry in enumerate(doc.get("cell", [])):
        where = f"reuse file {str(path)!r}, cell {k}"
        if not isinstance(entry, dict) or not {"track", "label", "objects"} <= set(entry):
            raise ValueError(f"{where}: needs 'track', 'label' and 'objects'")
        if entry["track"] not in TABLE_TRACKS:
            raise ValueError(f"{where}: unknown track {entry['track']!r}; valid: {', '.join(TABLE_TRACKS)}")
        if "scenes_of" in entry and entry["scenes_of"] not in TABLE_TRACKS:
            raise ValueError(f"{where}: unknown scenes_of track {entry['scenes_of']!r}; valid: {', '.join(TABLE_TRACKS)}")
        if ("evals" in entry) == ("table" in entry):
            raise ValueError(f"{where}: give one of 'evals' (a glob of mpg-eval JSON files) and 'table' (a tables.py report)")
        unknown = set(entry) - {"track", "label", "objects", "evals", "table", "scenes_of"}
        if unknown:
            raise ValueError(f"{where}: unknown keys {sorted(unknown)}")
        cell = ReusedCell(
            str(entry["track"]),
            str(entry["label"]),
            int(entry["objects"]),
            entry.get("evals"),
            entry.get("table"),
            entry.get("scenes_of"),
        )
        key = (cell.track, cell.label, cell.objects)
        if key in cells:
            raise ValueError(f"{where}: {key} is given twice")
        cells[key] = cell
    return cells
