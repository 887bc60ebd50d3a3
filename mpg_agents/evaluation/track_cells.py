"""A cell of the track table (:mod:`mpg_agents.evaluation.track_table`) and its file on disk.

A cell is (track, policy, object count): ``episodes`` episodes on the track's env from ``seed``
(:class:`CellRequest`). Its file, ``OUT/<track>/cells/<label>_<objects>.json``
(:func:`cell_file_name`), is ``mpg-eval --json``'s format with the policy entry it ran under
``table_policy`` (:func:`write_cell_file`), written whole; a cell run in blocks of seeds keeps
them in ``<cell>.blocks/`` (:func:`block_folder`). A recorded cell is used only when it is what
the table asks: the track's env, the object count, exactly the seeds
``seed .. seed + episodes - 1``, the same env options and the same policy entry; anything else
raises :class:`CellMismatchError` naming the file and what differs (:func:`read_cell_file`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mpg_agents.evaluation.eval_result import EvalResult
from mpg_agents.evaluation.evaluate import registered_options
from mpg_agents.evaluation.table_runs import PolicySpec, merged_result
from mpg_agents.evaluation.tables import TABLE_TRACKS, cell_json
from mpg_envs.policies.registry import baseline_name


def compared_entry(entry: Any) -> Any:
    """A policy entry as it is compared with another: a scripted baseline's former name read as
    its name (an entry recorded with ``grasp-only`` is one of ``pixel-heuristic``); anything else as it is."""
    if not isinstance(entry, dict) or not isinstance(entry.get("policy"), str):
        return entry
    return {**entry, "policy": baseline_name(entry["policy"]) or entry["policy"]}


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
        return TABLE_TRACKS[self.track].env_id

    def policy_entry(self) -> dict[str, Any]:
        """The policy-file entry, as a cell file records it."""
        return {"label": self.spec.label, "policy": self.spec.policy, **dict(self.spec.settings)}

    def recorded_env_options(self) -> dict[str, Any]:
        """The env options an evaluation of this cell records: the track's and the extra ones."""
        return json.loads(json.dumps({**registered_options(self.env_id), **dict(self.all_env_options)}))

    @property
    def all_env_options(self) -> tuple[tuple[str, Any], ...]:
        """The track's env keywords, then the extra ones (an extra one wins)."""
        return tuple({**dict(TABLE_TRACKS[self.track].env_options), **dict(self.env_options)}.items())

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


def read_cell_file(request: CellRequest, path: Path) -> dict[str, Any]:
    """A cell file this module wrote, checked against ``request`` (policy entry included)."""
    data = json.loads(path.read_text())
    if compared_entry(data.get("table_policy")) != compared_entry(request.policy_entry()):
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


def block_folder(path: Path) -> Path:
    """Where a cell run in blocks keeps its finished blocks: ``<cell>.blocks/<first seed>.json``."""
    return path.with_name(path.stem + ".blocks")
