"""Benchmark tracks beyond the stages: a registered id that is a stage run with fixed env
keywords (its own table rows), so a track is one name to evaluate on, not a list of options."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from mpg_envs.tasks.stages import STAGES

NOVEL_SCENE_TRIES = 100
"""Scene draws the unseen-object track allows before ``InvalidSceneError`` (the blocks' track
allows 20): a buried irregular object stays at most 30% visible less often than a block."""

NOVEL_GENERATOR: dict[str, Any] = {"buried_candidates": 5, "drop_settle_steps": 100, "drop_timestep": 0.004}
"""The unseen-object track's generator settings (``GeneratorConfig`` fields). Its scenes follow
the hard track's rules (the target one of the first five dropped, occluded, at most 30%
visible, every object at rest inside the workspace) and are made faster: any of the first
five may be the target (the buried one first), since occluders dropped onto an irregular
object often roll off it; each drop steps at 4 ms and settles for at most 100 steps before the
next object falls, and the whole pile must then be at rest under the env's own physics."""


@dataclass(frozen=True)
class TrackSpec:
    """A registered id: ``stage``'s env made with ``options`` (``gym.make`` keywords given by
    the caller override them)."""

    env_id: str
    stage: str
    options: dict[str, Any] = field(default_factory=dict)
    description: str = ""

    def __post_init__(self) -> None:
        if self.stage not in STAGES:
            raise ValueError(f"track {self.env_id}: unknown stage {self.stage!r}; valid: {sorted(STAGES)}")
        if "stage" in self.options:
            raise ValueError(f"track {self.env_id}: the stage is given by TrackSpec.stage, not options")

    @property
    def max_motions(self) -> int:
        return int(self.options.get("max_motions", STAGES[self.stage].max_motions))


TRACKS: dict[str, TrackSpec] = {
    t.env_id: t
    for t in (
        TrackSpec(
            "MPG-OccludedHardCamera-v0",
            "OccludedHard",
            {"obs_mode": "camera", "visual_randomization": True},
            "the hard track seen through two rendered RGB-D cameras with the default visual "
            "randomization (light, colours, a 1 cm / 1 degree camera calibration error, RealSense "
            "depth noise and holes), drawn from each episode's seed; needs OpenGL",
        ),
        TrackSpec(
            "MPG-OccludedHardNovel-v0",
            "OccludedHard",
            {"object_set": "random_urdfs_test", "config": {"scene_tries": NOVEL_SCENE_TRIES, "generator": NOVEL_GENERATOR}},
            "the hard track on objects no training uses: pybullet's random_urdfs test split (numbers "
            "ending in 0) fitted to the gripper, shipped as convex parts with the test scenes "
            "(no pybullet needed)",
        ),
        TrackSpec(
            "MPG-OccludedHardVisible-v0",
            "OccludedHard",
            {"target_spec": "visible"},
            "the hard track with the target's mask cut down to the pixels where it is the top surface "
            "(empty while it is hidden), as a modal segmenter gives; the same scenes seed for seed",
        ),
        TrackSpec(
            "MPG-OccludedHardExemplar-v0",
            "OccludedHard",
            {"target_spec": "exemplar"},
            "the hard track with the target named by pictures of it alone (query_color, query_depth) "
            "instead of a mask: the same scenes seed for seed, recoloured so that one object answers "
            "the query and look-alikes of its colour or shape surround it",
        ),
        TrackSpec(
            "MPG-OccludedHardNovelExemplar-v0",
            "OccludedHard",
            {
                "object_set": "random_urdfs_test",
                "config": {"scene_tries": NOVEL_SCENE_TRIES, "generator": NOVEL_GENERATOR},
                "target_spec": "exemplar",
            },
            "the unseen-object track with the target named by pictures of it alone, its scenes "
            "recoloured as the blocks' exemplar track's",
        ),
        TrackSpec(
            "MPG-OccludedHardCameraExemplar-v0",
            "OccludedHard",
            {"obs_mode": "camera", "visual_randomization": True, "target_spec": "exemplar"},
            "the camera track with the target named by pictures of it alone, taken through the same "
            "cameras with the episode's visual randomization; needs OpenGL",
        ),
    )
}
"""Track id -> spec; registered by ``import mpg_envs`` beside the stages' ids."""
