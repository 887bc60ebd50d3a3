"""The results tables: cells (policy, object count) of measured metrics, per track.

A table track (:class:`TableTrack`, by name in :data:`TABLE_TRACKS`) is a registered env id (a
stage's, or a track id of :data:`mpg_envs.tasks.tracks.TRACKS`) and what its table shows; adding
a track is one entry there (the env id) and one here (the table). ``table1`` is the paper's
Table I on ``MPG-Occluded-v0``: the paper's rows above the measured ones, task success rate
per object count, then average motion number per object count. ``hard`` is the strict
retrieval track ``MPG-OccludedHard-v0`` (target at most 30% visible, a mis-pick fails the
episode), which adds mis-picks per episode and the grasp success rate (target grasps /
grasp attempts); ``hard-novel`` and ``hard-camera`` are the same rules on unseen objects
(``MPG-OccludedHardNovel-v0``) and through rendered, visually randomized cameras
(``MPG-OccludedHardCamera-v0``). A measured cell shows its 95% intervals: Wilson for rates,
a seeded bootstrap for mean motions. :func:`rows_json` gives the same cells as data, keyed
by the policy's label, each with the name the policy gave itself; :func:`tracks_rows` lays
such cells of several tracks out as one table (track x policy x object count), and
:func:`tracks_success_rows` their success rates as a policy x (track, object count) grid.
A table holds cells of one MuJoCo major version (each cell's ``versions``; one recorded before
the MuJoCo version was reads as 3.x): cells of two raise
:class:`~mpg_envs.simulation.mujoco_version.MuJoCoVersionError`, since the same seeds make
other scenes and motions on another major version.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from mpg_agents.evaluation.eval_result import EvalResult
from mpg_envs.simulation.mujoco_version import check_one_mujoco, recorded_mujoco

ENV_ID = "MPG-Occluded-v0"


@dataclass(frozen=True)
class TableTrack:
    """One results table: the registered env id its cells run on, whether the paper's rows head it,
    its columns, what its scenes are, and env keywords beside the id's own."""

    name: str
    env_id: str
    paper_rows: bool
    strict_columns: bool  # mis-picks per episode and grasp success rate as columns
    scenes: str = ""  # what the track's scenes and observations are, for a combined table
    env_options: tuple[tuple[str, Any], ...] = ()  # env keywords of the track beside its env id's own


TABLE_TRACKS: dict[str, TableTrack] = {
    "table1": TableTrack("table1", ENV_ID, paper_rows=True, strict_columns=False, scenes="blocks, Table I's rules"),
    "hard": TableTrack("hard", "MPG-OccludedHard-v0", paper_rows=False, strict_columns=True, scenes="blocks"),
    "hard-novel": TableTrack(
        "hard-novel", "MPG-OccludedHardNovel-v0", paper_rows=False, strict_columns=True, scenes="unseen shapes"
    ),
    "hard-camera": TableTrack(
        "hard-camera", "MPG-OccludedHardCamera-v0", paper_rows=False, strict_columns=True, scenes="camera images of blocks"
    ),
    # Finding the target: the same scenes, the target named by its visible pixels or by an exemplar.
    "hard-visible": TableTrack(
        "hard-visible", "MPG-OccludedHardVisible-v0", paper_rows=False, strict_columns=True, scenes="blocks, visible mask"
    ),
    "hard-novel-visible": TableTrack(
        "hard-novel-visible",
        "MPG-OccludedHardNovel-v0",
        paper_rows=False,
        strict_columns=True,
        scenes="unseen shapes, visible mask",
        env_options=(("target_spec", "visible"),),
    ),
    "hard-camera-visible": TableTrack(
        "hard-camera-visible",
        "MPG-OccludedHardCamera-v0",
        paper_rows=False,
        strict_columns=True,
        scenes="camera images of blocks, visible mask",
        env_options=(("target_spec", "visible"),),
    ),
    "hard-exemplar": TableTrack(
        "hard-exemplar", "MPG-OccludedHardExemplar-v0", paper_rows=False, strict_columns=True, scenes="blocks, exemplar"
    ),
    "hard-novel-exemplar": TableTrack(
        "hard-novel-exemplar",
        "MPG-OccludedHardNovelExemplar-v0",
        paper_rows=False,
        strict_columns=True,
        scenes="unseen shapes, exemplar",
    ),
    "hard-camera-exemplar": TableTrack(
        "hard-camera-exemplar",
        "MPG-OccludedHardCameraExemplar-v0",
        paper_rows=False,
        strict_columns=True,
        scenes="camera images of blocks, exemplar",
    ),
}
"""The table tracks by name: the paper's Table I, the strict, hidden-target hard track, and the
hard track on unseen objects and on camera observations, and each of those three with the target
named by its visible pixels (``visible``) or by an exemplar image (``exemplar``)."""


@dataclass(frozen=True)
class PaperRow:
    """One method's published Table I figures: success rate and mean motions per object count."""

    method: str
    success: Mapping[int, float]
    motions: Mapping[int, float]


# Table I of the paper (50 tests per scenario; target one of the first five objects dropped).
PAPER_ROWS: tuple[PaperRow, ...] = (
    PaperRow("Grasping-Only", {15: 0.26, 30: 0.12}, {15: 6.46, 30: 8.33}),
    PaperRow("Target-Oriented VPG", {15: 0.32, 30: 0.26}, {15: 5.43, 30: 6.54}),
    PaperRow("Grasping the Invisible", {15: 0.72, 30: 0.66}, {15: 4.64, 30: 5.33}),
    PaperRow("Efficient Push-Grasping", {15: 0.84, 30: 0.74}, {15: 3.88, 30: 4.97}),
    PaperRow("MPGNet", {15: 0.92, 30: 0.84}, {15: 2.85, 30: 3.74}),
)


def cell_json(result: EvalResult) -> dict[str, Any]:
    """One cell's figures as data."""
    return {
        "name": result.policy,
        "episodes": result.episodes,
        "success": result.task_success_rate,
        "success_ci": list(result.success_interval),
        "motions": result.average_motions,
        "motions_ci": None if result.motions_interval is None else list(result.motions_interval),
        "motions_success": result.average_motions_success,
        "grasp_success_rate": result.grasp_success_rate,
        "grasp_attempts": result.grasp_attempts,
        "clean_success": result.clean_success_rate,
        "clean_success_ci": list(result.clean_success_interval),
        "mispicks_per_episode": result.mispicks_per_episode,
        "success_by_visibility": result.success_by_visibility,
        "end_reasons": dict(result.end_reasons),
        "primitive_counts": dict(result.primitive_counts),
        "env_options": dict(result.env_options),
        "versions": dict(result.versions),
        "finding": dict(result.finding),
    }


def rows_json(cells: Mapping[tuple[str, int], EvalResult]) -> dict[str, dict[str, dict[str, Any]]]:
    """``{policy: {"15": cell, "30": cell}}`` from cells keyed by (policy as asked, objects)."""
    rows: dict[str, dict[str, dict[str, Any]]] = {}
    for (policy, objects), result in cells.items():
        rows.setdefault(policy, {})[str(objects)] = cell_json(result)
    return rows


def paper_json(objects: Sequence[int]) -> dict[str, dict[str, dict[str, float]]]:
    """The paper's rows for the object counts it reports among ``objects``."""
    return {
        row.method: {str(n): {"success": row.success[n], "motions": row.motions[n]} for n in objects if n in row.success}
        for row in PAPER_ROWS
    }


def _success_text(cell: Mapping[str, Any]) -> str:
    lo, hi = cell["success_ci"]
    return f"{100 * cell['success']:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}]"


def _motions_text(cell: Mapping[str, Any]) -> str:
    if cell["motions_ci"] is None:
        return f"{cell['motions']:.2f}"
    lo, hi = cell["motions_ci"]
    return f"{cell['motions']:.2f} [{lo:.2f}, {hi:.2f}]"


def _success_motions_text(cell: Mapping[str, Any]) -> str:
    return f"{_success_text(cell)} in {cell['motions']:.2f}"


def _grasp_text(cell: Mapping[str, Any]) -> str:
    if cell["grasp_success_rate"] is None:
        return "n/a"
    return f"{100 * cell['grasp_success_rate']:.0f}% of {cell['grasp_attempts']}"


def check_table_mujoco(cells: Mapping[Any, Mapping[str, Any] | EvalResult]) -> int:
    """The one MuJoCo major version of a table's cells (:func:`cell_json` data or results,
    keyed by cell); raises :class:`~mpg_envs.simulation.mujoco_version.MuJoCoVersionError`
    naming every cell's version when they span major versions."""
    versions = {
        " ".join(map(str, key)) if isinstance(key, tuple) else str(key): recorded_mujoco(
            cell.versions if isinstance(cell, EvalResult) else cell.get("versions")
        )
        for key, cell in cells.items()
    }
    return check_one_mujoco(versions, "this table")


def _header(objects: Sequence[int], strict_columns: bool) -> list[str]:
    header = [f"success, {n} obj." for n in objects] + [f"motions, {n} obj." for n in objects]
    if strict_columns:
        header += [f"mis-picks/ep., {n} obj." for n in objects] + [f"grasp success, {n} obj." for n in objects]
    return header


def _cells_text(objects: Sequence[int], cells: Mapping[int, Mapping[str, Any]], strict_columns: bool) -> list[str]:
    """One row's figures, ``-`` where a cell was not run."""
    row = [_success_text(cells[n]) if n in cells else "-" for n in objects]
    row += [_motions_text(cells[n]) if n in cells else "-" for n in objects]
    if strict_columns:
        row += [f"{cells[n]['mispicks_per_episode']:.2f}" if n in cells else "-" for n in objects]
        row += [_grasp_text(cells[n]) if n in cells else "-" for n in objects]
    return row


def _row_label(policy: str, results: Sequence[EvalResult]) -> str:
    """The name the policy gave itself (it says e.g. which branches a net has), else as asked."""
    names = list(dict.fromkeys(r.policy for r in results))
    return " / ".join(names) if names else policy


def table_rows(
    policies: Sequence[str],
    objects: Sequence[int],
    cells: Mapping[tuple[str, int], EvalResult],
    track: TableTrack = TABLE_TRACKS["table1"],
    labels: Mapping[str, str] | None = None,
) -> tuple[list[str], list[list[str]], int]:
    """Header, body rows (the paper's first on a track that shows them, then the measured
    ones) and how many paper rows. A row is named ``labels[policy]`` where given, else by
    the name the policy gave itself. Cells of two MuJoCo major versions raise
    :class:`~mpg_envs.simulation.mujoco_version.MuJoCoVersionError`."""
    check_table_mujoco(cells)
    header = ["Method"] + _header(objects, track.strict_columns)
    body = []
    if track.paper_rows:
        for paper in PAPER_ROWS:
            success = [f"{100 * paper.success[n]:.0f}%" if n in paper.success else "-" for n in objects]
            motions = [f"{paper.motions[n]:.2f}" if n in paper.motions else "-" for n in objects]
            body.append([f"{paper.method} (paper)"] + success + motions)
    paper_count = len(body)
    for policy in policies:
        results = [cells[(policy, n)] for n in objects if (policy, n) in cells]
        row = [labels[policy] if labels and policy in labels else _row_label(policy, results)]
        row += _cells_text(
            objects, {n: cell_json(cells[(policy, n)]) for n in objects if (policy, n) in cells}, track.strict_columns
        )
        body.append(row)
    return header, body, paper_count


def tracks_rows(
    tracks: Sequence[str],
    policies: Sequence[str],
    objects: Sequence[int],
    cells: Mapping[tuple[str, str, int], Mapping[str, Any]],
) -> tuple[list[str], list[list[str]]]:
    """Header and rows of one table over several strict tracks: a row per (track, policy)
    with at least one cell, tracks in ``tracks``' order, policies in ``policies``' order;
    ``cells`` maps (track, policy label, objects) to :func:`cell_json`'s data. A cell not
    run is ``-``. Raises ``ValueError`` for a track without the strict columns (Table I's
    rows have no mis-pick and grasp columns to share), and
    :class:`~mpg_envs.simulation.mujoco_version.MuJoCoVersionError` for cells of two MuJoCo
    major versions."""
    check_table_mujoco(cells)
    for name in tracks:
        if name not in TABLE_TRACKS or not TABLE_TRACKS[name].strict_columns:
            raise ValueError(
                f"tracks_rows lays out strict tracks only, got {name!r}; "
                f"valid: {[t for t, s in TABLE_TRACKS.items() if s.strict_columns]}"
            )
    header = ["Track", "Method"] + _header(objects, True)
    body = []
    for name in tracks:
        track = TABLE_TRACKS[name]
        for policy in policies:
            mine = {n: cells[(name, policy, n)] for n in objects if (name, policy, n) in cells}
            if mine:
                body.append([f"{track.scenes} ({track.env_id})", policy] + _cells_text(objects, mine, True))
    return header, body


def tracks_success_rows(
    tracks: Sequence[str],
    policies: Sequence[str],
    objects: Sequence[int],
    cells: Mapping[tuple[str, str, int], Mapping[str, Any]],
) -> tuple[list[str], list[list[str]]]:
    """The same cells as :func:`tracks_rows`, one row per policy with at least one cell and a
    column per (track, object count): success rate [95% interval] in mean motions, ``-``
    where a cell was not run. Tracks with no cell at all get no column. Cells of two MuJoCo
    major versions raise :class:`~mpg_envs.simulation.mujoco_version.MuJoCoVersionError`."""
    check_table_mujoco(cells)
    columns = [(name, n) for name in tracks for n in objects if any((name, p, n) in cells for p in policies)]
    header = ["Method"] + [f"{TABLE_TRACKS[name].scenes}, {n} obj." for name, n in columns]
    body = []
    for policy in policies:
        row = [_success_motions_text(cells[(name, policy, n)]) if (name, policy, n) in cells else "-" for name, n in columns]
        if any(c != "-" for c in row):
            body.append([policy] + row)
    return header, body


def format_text(header: list[str], body: list[list[str]], paper_rows: int) -> str:
    """A fixed-width table, a rule between the paper's rows and the measured ones."""
    widths = [max(len(r[i]) for r in [header] + body) for i in range(len(header))]

    def line(cells: list[str]) -> str:
        return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))

    rule = "-" * len(line(header))
    paper = [line(r) for r in body[:paper_rows]] + [rule] if paper_rows else []
    return "\n".join([line(header), rule] + paper + [line(r) for r in body[paper_rows:]])


def format_markdown(header: list[str], body: list[list[str]], text_columns: int = 1) -> str:
    """The same table as GitHub Markdown: the first ``text_columns`` columns aligned left,
    the figures right."""
    lines = [
        "| " + " | ".join(header) + " |",
        "|" + "|".join(["---"] * text_columns + ["---:"] * (len(header) - text_columns)) + "|",
    ]
    lines += ["| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in body]
    return "\n".join(lines)
