"""What an evaluation records: one episode's :class:`EpisodeRecord` and the summary of many, an
:class:`EvalResult` (the paper's metrics and the ones beside them, their 95% intervals, the
episodes that raised), as a table to print and as JSON (``mpg-eval --json``).

:func:`mpg_agents.evaluation.evaluate.run_episode` makes the records and
:func:`mpg_agents.evaluation.evaluate.summarise` the result.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from mpg_agents.evaluation.failures import EpisodeFailure, describe_failures, failures_line
from mpg_agents.evaluation.finding import finding_line
from mpg_agents.evaluation.motion_log import MotionRecord


@dataclass(frozen=True)
class EpisodeRecord:
    """What one episode did; wall time is kept out of equality and JSON."""

    index: int
    seed: int
    success: bool
    motions: int
    end_reason: str
    primitives: dict[str, int]  # motions per primitive
    grasp_attempts: int
    target_grasps: int  # grasps that lifted the target
    wrong_grasps: int  # grasps that lifted another object
    objects_left: int | None
    visible_fraction: float | None = None  # the target's visible fraction at reset
    # The actions taken, to replay or compare an episode: flat indices, or for a wrapped env
    # with a continuous action space (mpg_envs.integrations.wrappers.ContinuousAction) tuples of floats.
    actions: tuple[int | tuple[float, ...], ...] = ()
    visuals: dict[str, Any] | None = None  # the episode's drawn visual randomization (env option visual_randomization)
    steps: tuple[MotionRecord, ...] = ()  # what each motion met (mpg_agents.evaluation.motion_log)
    first_sight: int | None = None  # motions until the target first showed (mpg_agents.evaluation.finding)
    lookalike_grasps: int | None = None  # mis-picks of a look-alike (exemplar envs; None: not reported)
    seconds: float = field(default=0.0, compare=False)

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        del data["seconds"]
        if data["visuals"] is None:  # records of envs without visual randomization stay as they were
            del data["visuals"]
        if data["lookalike_grasps"] is None:  # only exemplar envs report look-alikes
            del data["lookalike_grasps"]
        return data

    @property
    def clean_success(self) -> bool:
        """Succeeded without a mis-pick (no grasp lifted another object first)."""
        return self.success and self.wrong_grasps == 0

    def describe(self) -> str:
        outcome = "success" if self.success else "failure"
        used = ", ".join(f"{n} {p}" for p, n in self.primitives.items() if n)
        return (
            f"episode {self.index} (seed {self.seed}): {outcome} after {self.motions} motions ({used}); end: {self.end_reason}"
        )


@dataclass
class EvalResult:
    """The paper's metrics, their 95% intervals, and the episodes they were measured on."""

    policy: str
    env_id: str
    num_objects: int
    episodes: int
    seed: int
    task_success_rate: float  # episodes ending with the target grasped
    success_interval: tuple[float, float]  # Wilson 95%
    average_motions: float  # mean motions per episode (failures count all their motions)
    motions_interval: tuple[float, float] | None  # bootstrap 95% (None for one episode)
    average_motions_success: float | None  # mean motions of the successful episodes
    grasp_success_rate: float | None  # target grasps / grasp attempts
    grasp_attempts: int
    end_reasons: dict[str, int]
    primitive_counts: dict[str, int]  # motions per primitive over all episodes
    records: list[EpisodeRecord]
    seconds_per_motion: float
    wall_seconds: float = 0.0
    workers: int = 1
    clean_success_rate: float = 0.0  # success without a mis-pick
    clean_success_interval: tuple[float, float] = (0.0, 1.0)  # Wilson 95%
    mispicks_per_episode: float = 0.0  # grasps that lifted a non-target object, per episode
    # visibility band at reset -> {"episodes", "successes", "rate", "interval"}
    success_by_visibility: dict[str, dict[str, Any]] = field(default_factory=dict)
    env_options: dict[str, Any] = field(default_factory=dict)  # keywords the env was made with
    versions: dict[str, str] = field(default_factory=dict)  # package, env and MuJoCo versions
    # episodes that raised instead of ending (seed and error; the metrics are over the others)
    failures: list[EpisodeFailure] = field(default_factory=list)
    # motions to first sight and look-alike grasps (mpg_agents.evaluation.finding.finding_summary)
    finding: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready data; wall time and the worker count are left out so one seed gives one file."""
        data = asdict(self)
        for key in ("seconds_per_motion", "wall_seconds", "workers"):
            del data[key]
        data["records"] = [r.to_dict() for r in self.records]
        data["failures"] = [f.to_dict() for f in self.failures]
        return data

    def failures_line(self) -> str:
        """One line naming the episodes that failed and why (``""`` when none did)."""
        return failures_line(self.failures, self.episodes)

    def table(self) -> str:
        lo, hi = self.success_interval
        motions = f"{self.average_motions:.2f}"
        if self.motions_interval is not None:
            motions += f" [{self.motions_interval[0]:.2f}, {self.motions_interval[1]:.2f}]"
        rows = [
            ("policy", self.policy),
            (
                "env",
                f"{self.env_id} ({self.num_objects} objects)" + "".join(f", {k}={v}" for k, v in self.env_options.items()),
            ),
            (
                "episodes",
                f"{self.episodes} (seeds {self.seed}..{self.seed + self.episodes + len(self.failures) - 1}"
                + (f"; {len(self.failures)} more failed, left out)" if self.failures else ")"),
            ),
            *((("failed", describe_failures(self.failures)),) if self.failures else ()),
            ("task success rate", f"{100 * self.task_success_rate:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}]"),
            ("average motion number", motions),
            (
                "  in successful episodes",
                "n/a" if self.average_motions_success is None else f"{self.average_motions_success:.2f}",
            ),
            (
                "  without a mis-pick",
                f"{100 * self.clean_success_rate:.1f}% [{100 * self.clean_success_interval[0]:.1f}, "
                f"{100 * self.clean_success_interval[1]:.1f}]",
            ),
            ("mis-picks per episode", f"{self.mispicks_per_episode:.2f}"),
            (
                "grasp success rate",
                "n/a" if self.grasp_success_rate is None else f"{100 * self.grasp_success_rate:.1f}% of {self.grasp_attempts}",
            ),
            ("finding the target", finding_line(self.finding)),
            (
                "success by visibility",
                ", ".join(f"{band}: {c['successes']}/{c['episodes']}" for band, c in self.success_by_visibility.items())
                or "n/a",
            ),
            ("primitives used", ", ".join(f"{p} {n}" for p, n in self.primitive_counts.items())),
            ("episodes ended by", ", ".join(f"{r} {n}" for r, n in self.end_reasons.items())),
            (
                "seconds per motion",
                f"{self.seconds_per_motion:.2f} ({self.workers} "
                f"worker{'s' if self.workers > 1 else ''}, {self.wall_seconds:.1f} s)",
            ),
        ]
        width = max(len(k) for k, _ in rows)
        return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)
