"""The finding table: how a policy found the target on each track, beside the track table.

For each (track, policy) cell whose episodes kept it (:func:`mpg_agents.evaluation.finding.finding_summary`):
in how many episodes the target showed at reset, in how many it was ever seen, the mean motions to
first sight of those, and on exemplar tracks the look-alike grasps and the other mis-picks per
episode. Cells laid out as :func:`mpg_agents.evaluation.tables.tracks_rows` lays them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from mpg_agents.evaluation.tables import TABLE_TRACKS

FINDING_COLUMNS = ("shown at reset", "ever seen", "motions to first sight", "look-alike grasps/ep.", "other mis-picks/ep.")
"""The columns of each object count, in order."""


def finding_cells_text(finding: Mapping[str, Any]) -> list[str]:
    """One cell's :data:`FINDING_COLUMNS` as text (``n/a`` where the episodes did not report it)."""
    episodes = finding.get("episodes") or 0
    if not episodes:
        return ["n/a"] * len(FINDING_COLUMNS)
    mean = finding.get("motions_to_sight")
    looks = finding.get("lookalike_grasps_per_episode")
    others = finding.get("other_mispicks_per_episode")
    return [
        f"{finding['shown_at_reset']} of {episodes}",
        f"{finding['sighted']} of {episodes}",
        "n/a" if mean is None else f"{mean:.2f}",
        "n/a" if looks is None else f"{looks:.2f}",
        "n/a" if others is None else f"{others:.2f}",
    ]


def finding_rows(
    tracks: Sequence[str],
    policies: Sequence[str],
    objects: Sequence[int],
    cells: Mapping[tuple[str, str, int], Mapping[str, Any]],
) -> tuple[list[str], list[list[str]]]:
    """Header and rows: one row per (track, policy, object count) whose cell reports finding
    (``cells`` maps (track, policy label, objects) to
    :func:`~mpg_agents.evaluation.tables.cell_json` data); tracks, policies and object counts in
    the order given. Raises ``ValueError`` for a track :data:`~mpg_agents.evaluation.tables.TABLE_TRACKS`
    does not have."""
    unknown = [name for name in tracks if name not in TABLE_TRACKS]
    if unknown:
        raise ValueError(f"unknown tracks {unknown}; valid: {list(TABLE_TRACKS)}")
    header = ["Track", "Method", "objects", *FINDING_COLUMNS]
    body = []
    for name in tracks:
        for policy in policies:
            for n in objects:
                cell = cells.get((name, policy, n))
                if cell and cell.get("finding", {}).get("episodes"):
                    body.append([f"{TABLE_TRACKS[name].scenes} ({TABLE_TRACKS[name].env_id})", policy, str(n)])
                    body[-1] += finding_cells_text(cell["finding"])
    return header, body
