"""Episodes that raised: what failed and why, kept beside the records of those that finished.

An evaluation that meets an error in one episode (a scene that cannot be made for its seed, a
case's scene that cannot be loaded) records it as an :class:`EpisodeFailure` and goes on with
the next episode, so that the episodes that finished are summarised and written, and the
result says which seeds (or case runs) failed and why. :func:`failures_line` says it in one
line for a command line's stderr (the same error told once, :func:`describe_failures`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

__all__ = ["EpisodeFailure", "NothingFinished", "describe_failures", "failures_line"]


class NothingFinished(RuntimeError):
    """Every episode of an evaluation failed: nothing to summarise (the message lists the failures)."""


@dataclass(frozen=True)
class EpisodeFailure:
    """One episode that raised instead of ending.

    Attributes:
        index: the episode's index in its evaluation (the run's index for a case).
        seed: the seed its reset was given.
        error: the exception's type name, e.g. ``"InvalidSceneError"``.
        message: the exception's message (its first line).
        case: the case it was a run of (``None`` for a seeded episode).
    """

    index: int
    seed: int
    error: str
    message: str
    case: str | None = None

    @classmethod
    def of(cls, exc: BaseException, index: int, seed: int, case: str | None = None) -> EpisodeFailure:
        """The failure of episode ``index`` (reset with ``seed``) that raised ``exc``."""
        message = str(exc).strip().splitlines()[0] if str(exc).strip() else repr(exc)
        return cls(int(index), int(seed), type(exc).__name__, message, case)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready data (``case`` left out for a seeded episode)."""
        data = asdict(self)
        if data["case"] is None:
            del data["case"]
        return data

    def describe(self) -> str:
        """``"seed 2: InvalidSceneError: ..."`` or ``"case 'stack' run 0 (seed 1000): ..."``."""
        where = f"seed {self.seed}" if self.case is None else f"case {self.case!r} run {self.index} (seed {self.seed})"
        return f"{where}: {self.error}: {self.message}"


def describe_failures(failures: Sequence[EpisodeFailure]) -> str:
    """The failures in one line, those with the same error told once: ``"seeds 0, 2:
    InvalidSceneError: ..."``, ``"case 'stack' run 1 (seed 1001): ..."``."""
    groups: dict[tuple[str, str], list[EpisodeFailure]] = {}
    for failure in failures:
        groups.setdefault((failure.error, failure.message), []).append(failure)
    parts = []
    for (error, message), group in groups.items():
        seeded = [f.seed for f in group if f.case is None]
        where = [f"seed{'s' if len(seeded) > 1 else ''} {', '.join(map(str, seeded))}"] if seeded else []
        where += [f"case {f.case!r} run {f.index} (seed {f.seed})" for f in group if f.case is not None]
        parts.append(f"{', '.join(where)}: {error}: {message}")
    return "; ".join(parts)


def failures_line(failures: Sequence[EpisodeFailure], finished: int, what: str = "episodes") -> str:
    """One line saying how many of the ``what`` failed (of ``finished`` plus the failures) and
    why (:func:`describe_failures`); ``""`` when none did."""
    if not failures:
        return ""
    total = finished + len(failures)
    return f"{len(failures)} of {total} {what} failed ({finished} finished and kept): {describe_failures(failures)}"
