"""What each motion of an evaluated episode met: the target's cover and visible fraction before
it, and what a grasp lifted.

An episode's :class:`MotionRecord` tuple (``EpisodeRecord.steps``, written by ``mpg-eval
--json``) answers where two policies part: at which visibility one grasps and the other still
uncovers. :func:`motions_by_visibility` counts a policy's motions by primitive, cover and the
visibility band (:data:`mpg_envs.perception.occlusion.VISIBILITY_BANDS`) of the target before
the motion, and :func:`uncovering_outcomes` how often a move or push on a covered target
left it uncovered; ``benchmarks/visibility_steps.py`` prints both for ``mpg-eval --json`` files.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from mpg_envs.grid.actions import PRIMITIVES
from mpg_envs.grid.primitive_specs import GRASP, MOVE, PUSH
from mpg_envs.perception.occlusion import VISIBILITY_BAND_LABELS, visibility_band


@dataclass(frozen=True)
class MotionRecord:
    """One motion: its primitive, the target before it, and (for a grasp) what came up."""

    primitive: str
    covered_before: bool | None  # the env's occlusion flag before the motion (None: not reported)
    visible_before: float | None  # the target's visible fraction before the motion (None: not reported)
    target_grasped: bool = False
    wrong_grasp: bool = False  # the grasp lifted another object

    @classmethod
    def from_info(cls, info: Mapping[str, Any], visible_before: float | None) -> MotionRecord:
        """The record of a step from its ``info`` and the visible fraction the step started from
        (the reset's or the previous step's ``info["visible_fraction"]``)."""
        covered = info.get("occluded_before")
        return cls(
            primitive=str(info["primitive"]),
            covered_before=None if covered is None else bool(covered),
            visible_before=None if visible_before is None else float(visible_before),
            target_grasped=bool(info.get("target_grasped", False)),
            wrong_grasp=bool(info.get("wrong_grasp", False)),
        )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> MotionRecord:
        """A record read back from JSON (:func:`dataclasses.asdict`'s keys).

        Raises:
            ValueError: an unknown primitive or missing keys, naming them.
        """
        missing = {"primitive", "covered_before", "visible_before"} - set(data)
        if missing:
            raise ValueError(f"a motion record needs {sorted(missing)}; got keys {sorted(data)}")
        if data["primitive"] not in PRIMITIVES:
            raise ValueError(f"a motion's primitive must be one of {PRIMITIVES}, got {data['primitive']!r}")
        return cls(
            **{
                k: data[k]
                for k in ("primitive", "covered_before", "visible_before", "target_grasped", "wrong_grasp")
                if k in data
            }
        )


@dataclass(frozen=True)
class VisibilityCount:
    """Motions of one primitive, cover and visibility band, and (for grasps) what they lifted."""

    motions: int = 0
    target_grasps: int = 0
    wrong_grasps: int = 0


def motions_by_visibility(steps: Iterable[MotionRecord]) -> dict[tuple[str, bool, str], VisibilityCount]:
    """Counts of ``steps`` keyed by ``(primitive, covered_before, band)``, in primitive, cover
    (covered first) and band order; motions whose cover or visible fraction the env did not
    report are left out.

    Raises:
        ValueError: a visible fraction outside [0, 1] (:func:`~mpg_envs.perception.occlusion.visibility_band`).
    """
    counts: dict[tuple[str, bool, str], list[int]] = {}
    for step in steps:
        if step.covered_before is None or step.visible_before is None:
            continue
        key = (step.primitive, step.covered_before, str(visibility_band(step.visible_before)))
        tally = counts.setdefault(key, [0, 0, 0])
        tally[0] += 1
        tally[1] += int(step.target_grasped)
        tally[2] += int(step.wrong_grasp)
    order = {
        (p, c, b): (i, j, k)
        for i, p in enumerate(PRIMITIVES)
        for j, c in enumerate((True, False))
        for k, b in enumerate(VISIBILITY_BAND_LABELS)
    }
    return {key: VisibilityCount(*counts[key]) for key in sorted(counts, key=order.__getitem__)}


def uncovering_outcomes(episodes: Iterable[Sequence[MotionRecord]]) -> tuple[int, int]:
    """``(freed, counted)``: of the moves and pushes made while the target was covered and
    followed by another motion of the same episode, how many left it uncovered (the next
    motion's ``covered_before`` false). An episode's last motion has no next one to tell, and
    motions whose cover the env did not report are left out."""
    freed = counted = 0
    for steps in episodes:
        for step, after in zip(steps, steps[1:]):
            if step.primitive in (MOVE, PUSH) and step.covered_before and after.covered_before is not None:
                counted += 1
                freed += int(not after.covered_before)
    return freed, counted


def visibility_table(counts: Mapping[tuple[str, bool, str], VisibilityCount], episodes: int) -> str:
    """A Markdown table of :func:`motions_by_visibility`'s counts: a row per primitive and
    cover, a column per visibility band (motions, and for grasps how many took the target),
    and motions per episode over ``episodes``.

    Raises:
        ValueError: ``episodes`` below 1.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    header = "| motion | target | " + " | ".join(f"visible {b}" for b in VISIBILITY_BAND_LABELS) + " | per episode |"
    lines = [header, "| " + " | ".join(["---"] * (len(VISIBILITY_BAND_LABELS) + 3)) + " |"]
    for primitive in PRIMITIVES:
        for covered in (True, False):
            row = {b: counts.get((primitive, covered, b)) for b in VISIBILITY_BAND_LABELS}
            total = sum(c.motions for c in row.values() if c is not None)
            if not total:
                continue
            cells = [_cell(primitive, c) for c in row.values()]
            lines.append(
                f"| {primitive} | {'covered' if covered else 'uncovered'} | "
                + " | ".join(cells)
                + f" | {total / episodes:.2f} |"
            )
    return "\n".join(lines)


def _cell(primitive: str, count: VisibilityCount | None) -> str:
    """``motions`` (grasps: ``motions (target T, other W)``), ``.`` for none."""
    if count is None or not count.motions:
        return "."
    if primitive != GRASP:
        return str(count.motions)
    wrong = f", other {count.wrong_grasps}" if count.wrong_grasps else ""
    return f"{count.motions} (target {count.target_grasps}{wrong})"
