"""The paper's multi-stage training pipeline (Section III-C), driven by the stage table.

The stages run in order (:data:`~mpg_agents.learning.training_stages.TRAINING_STAGES` by default), each
starting from the previous stage's weights, and with them the Q*_g they carry (the run's
``--q-star``, if given, is the first stage's). A stage that ``calibrates_q_star`` estimates Q*_g
from its own successful grasps and its weights become the discriminator of the stages that
``uses_discriminator``; a stage with ``calibration_episodes`` calibrates Q*_g again in its own
scenes. ``pipeline.json`` records the final weights and the one Q*_g they carry. Ablations are
changes of the table (:func:`~mpg_agents.learning.stage_variants.without_multistage`,
:func:`~mpg_agents.learning.stage_variants.without_alternation`).

Each stage writes to ``out/<stage name>/`` and resumes there if interrupted; finished stages
are skipped on a re-run.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from mpg_agents.acting.grasp_threshold import UNCALIBRATED, as_record, from_header
from mpg_agents.acting.weights import read_checkpoint_header
from mpg_agents.learning.learner import Learner
from mpg_agents.learning.run_folder import RunLock, prepare_run_folder
from mpg_agents.learning.train_config import TrainConfig, json_safe
from mpg_agents.learning.training_stages import TRAINING_STAGES, TrainingStage
from mpg_envs.files import write_text_whole


@dataclass
class PipelineConfig:
    """The stages to run and one base :class:`TrainConfig` for the algorithm's settings."""

    base: TrainConfig = field(default_factory=TrainConfig)
    stages: tuple[TrainingStage, ...] = TRAINING_STAGES


def run_pipeline(
    cfg: PipelineConfig,
    out: str | Path,
    init: str | None = None,
    log: Callable[[str], None] = print,
    resume_anyway: bool = False,
) -> dict[str, Any]:
    """Run the stages in order; returns ``{stage: summary}`` plus the final weights and their Q*_g.

    ``out`` is locked while it runs (:class:`~mpg_agents.learning.run_folder.RunLock`); a stage
    resumed with other settings than it was saved with refuses unless ``resume_anyway``.
    """
    out = prepare_run_folder(out)
    with RunLock(out):
        return _run_stages(cfg, out, init, log, resume_anyway)


def _run_stages(
    cfg: PipelineConfig, out: Path, init: str | None, log: Callable[[str], None], resume_anyway: bool
) -> dict[str, Any]:
    summary: dict[str, Any] = {}
    weights = init
    discriminator: str | None = cfg.base.discriminator
    for i, stage in enumerate(cfg.stages):
        # A later stage starts with the Q*_g its starting weights carry.
        q_star = cfg.base.q_star if i == 0 else UNCALIBRATED
        stage_cfg = replace(cfg.base, q_star=q_star, discriminator=discriminator if stage.uses_discriminator else None)
        stage_dir = out / stage.name
        done = stage_dir / "done.json"
        if done.is_file():
            log(f"{stage.name}: already finished, skipping")
            result = json.loads(done.read_text())
        else:
            learner = Learner(stage_cfg, stage, stage_dir, init=weights, log=log, resume_anyway=resume_anyway)
            log(f"{stage.name}: {learner.steps} iterations, training {learner.trainable}, init {weights}")
            result = json_safe(learner.run())
            write_text_whole(done, json.dumps(result))
        summary[stage.name] = result
        weights = str(stage_dir / "weights.safetensors")
        if stage.calibrates_q_star:
            discriminator = weights
    summary["q_star"] = as_record(from_header(read_checkpoint_header(weights)) if weights is not None else UNCALIBRATED)
    summary["final_weights"] = weights
    # The record ships beside its weights: paths inside the run are written relative to it.
    record = {**summary, "final_weights": _relative_to(weights, out)}
    write_text_whole(out / "pipeline.json", json.dumps(json_safe(record), indent=1))
    return summary


def _relative_to(path: str | None, root: Path) -> str | None:
    """``path`` relative to ``root`` when it lies inside it, else unchanged."""
    if path is None:
        return None
    try:
        return Path(path).resolve().relative_to(root.resolve()).as_posix()
    except ValueError:
        return path
