"""What finding the target cost an episode: motions to first sight, and grasps on look-alikes.

- Motions to first sight: the first motion after which any part of the target shows (its
  visible fraction above 0); 0 when it shows at reset; ``None`` when it never showed, or when
  the env does not report the visible fraction (an episode record's ``visible_fraction`` at
  reset is ``None`` then).
- Look-alike grasps (exemplar envs, ``target_spec="exemplar"``): mis-picks that lifted an
  object sharing the target's colour or shape (``info["wrong_grasp_lookalike"]``), counted
  apart from the other mis-picks; ``None`` for an env that does not report them.

:func:`finding_summary` puts an evaluation's episodes together (``EvalResult.finding``, in
``mpg-eval --json``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np


class FindingRecord(Protocol):
    """What :func:`finding_summary` reads of an episode record (read-only: frozen records qualify)."""

    @property
    def visible_fraction(self) -> float | None: ...

    @property
    def first_sight(self) -> int | None: ...

    @property
    def lookalike_grasps(self) -> int | None: ...

    @property
    def wrong_grasps(self) -> int: ...


def first_sight(visible_at_reset: float | None, visible_after: Sequence[float | None]) -> int | None:
    """The motions after which the target first showed: 0 when ``visible_at_reset`` is above 0,
    else the first ``k`` whose ``visible_after[k - 1]`` (the visible fraction after motion ``k``)
    is; ``None`` when it never did or the reset reported none."""
    if visible_at_reset is None:
        return None
    if visible_at_reset > 0:
        return 0
    for k, visible in enumerate(visible_after, start=1):
        if visible is not None and visible > 0:
            return k
    return None


def lookalike_grasp(info: Mapping[str, Any]) -> bool | None:
    """Whether a step's mis-pick lifted a look-alike (``None``: the env does not report it)."""
    value = info.get("wrong_grasp_lookalike")
    return None if value is None else bool(value)


class FindingTally:
    """An episode's finding values, step by step: ``FindingTally(visible_at_reset)``, then
    :meth:`step` with each step's ``info``; :attr:`first_sight` and :attr:`lookalike_grasps`."""

    def __init__(self, visible_at_reset: float | None):
        self.visible_at_reset = None if visible_at_reset is None else float(visible_at_reset)
        self.visible_after: list[float | None] = []
        self.lookalike_grasps: int | None = None  # None: the env reports no look-alikes

    def step(self, info: Mapping[str, Any]) -> None:
        """Count a step from its ``info`` (its visible fraction, a look-alike mis-pick)."""
        self.visible_after.append(info.get("visible_fraction"))
        told = lookalike_grasp(info)
        if told is not None:
            self.lookalike_grasps = (self.lookalike_grasps or 0) + int(told)

    @property
    def first_sight(self) -> int | None:
        """:func:`first_sight` of the steps so far."""
        return first_sight(self.visible_at_reset, self.visible_after)


def finding_summary(records: Iterable[FindingRecord]) -> dict[str, Any]:
    """Over the episodes reporting the target's visibility (none if any was recorded before first
    sight was kept): how many (``episodes``), in how
    many it showed at reset (``shown_at_reset``) or ever (``sighted``), and the mean motions to
    first sight of the sighted ones (``motions_to_sight``, ``None`` when none); over the ones
    reporting look-alikes: look-alike grasps and other mis-picks per episode
    (``lookalike_grasps_per_episode``, ``other_mispicks_per_episode``; absent when none reports them)."""
    records = list(records)
    seen = [r for r in records if r.visible_fraction is not None]
    # A target visible at reset is first seen at motion 0: records that say otherwise were written
    # before first sight was kept, and episodes pooled with them say nothing of finding either.
    if any(r.visible_fraction is not None and r.visible_fraction > 0 and r.first_sight is None for r in records):
        seen = []
    sights = [r.first_sight for r in seen if r.first_sight is not None]
    summary: dict[str, Any] = {
        "episodes": len(seen),
        "shown_at_reset": sum(s == 0 for s in sights),
        "sighted": len(sights),
        "motions_to_sight": float(np.mean(sights)) if sights else None,
    }
    told = [r for r in records if r.lookalike_grasps is not None]
    if told:
        lookalikes = sum(int(r.lookalike_grasps or 0) for r in told)  # none is None here
        summary["lookalike_grasps_per_episode"] = lookalikes / len(told)
        summary["other_mispicks_per_episode"] = (sum(r.wrong_grasps for r in told) - lookalikes) / len(told)
    return summary


def finding_line(summary: Mapping[str, Any]) -> str:
    """The summary as one line of the evaluation's table (``"n/a"`` without reports)."""
    if not summary.get("episodes"):
        return "n/a"
    mean = summary["motions_to_sight"]
    line = (
        f"{summary['sighted']}/{summary['episodes']} sighted ({summary['shown_at_reset']} at reset), "
        f"{'n/a' if mean is None else f'{mean:.2f}'} motions to first sight"
    )
    if "lookalike_grasps_per_episode" in summary:
        line += (
            f"; look-alike grasps {summary['lookalike_grasps_per_episode']:.2f}, "
            f"other mis-picks {summary['other_mispicks_per_episode']:.2f} per episode"
        )
    return line
