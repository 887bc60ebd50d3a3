"""The five-stage training pipeline of the paper (Section III-C) and its ablations.

I target-agnostic grasping (Stage1) -> II target-oriented grasping (Stage2) -> calibrate
Q*_g from the grasp net -> III moving (Stage3; the Stage II grasp net, frozen, scores states
for the rewards; objects grow from 2) -> IV pushing (Stage4; grasp and move nets frozen) ->
V joint training (Stage5; the three nets trained in turn, the other two frozen).

Ablations: ``multistage=False`` starts at V from scratch ("w/o mt"); ``alternating=False``
trains all three nets together in V with actions chosen by the largest Q ("w/o at").
Each stage writes to ``out/<stage>/`` and resumes there if interrupted; finished stages are
skipped on a re-run.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

from mpg_agents.learner import Learner, TrainConfig, json_safe


@dataclass
class PipelineConfig:
    """Iterations per stage and the ablation switches (one base TrainConfig for the rest)."""

    base: TrainConfig = field(default_factory=TrainConfig)
    stage_steps: dict[str, int] = field(
        default_factory=lambda: {"Stage1": 500, "Stage2": 1000, "Stage3": 600, "Stage4": 600, "Stage5": 1500}
    )
    stages: tuple[str, ...] = ("Stage1", "Stage2", "Stage3", "Stage4", "Stage5")
    multistage: bool = True
    alternating: bool = True
    stage3_objects: tuple[int, int] = (2, 4)  # curriculum: from 2 objects to this many
    alternate_every: int = 50


def stage_configs(cfg: PipelineConfig) -> list[TrainConfig]:
    """The per-stage training configs, in order (the ablations change which and how)."""
    b = cfg.base
    stages = cfg.stages if cfg.multistage else ("Stage5",)
    out = []
    for name in stages:
        steps = cfg.stage_steps[name]
        common = dict(env_id=f"MPG-{name}-v0", steps=steps, epsilon_decay_steps=steps)
        if name in ("Stage1", "Stage2"):
            out.append(replace(b, **common, trainable=("grasp",)))
        elif name == "Stage3":
            start, end = cfg.stage3_objects
            out.append(replace(b, **common, trainable=("move",), num_objects_start=start, num_objects=end))
        elif name == "Stage4":
            out.append(replace(b, **common, trainable=("push",)))
        elif name == "Stage5":
            if cfg.alternating:
                out.append(replace(b, **common, trainable=("move", "push", "grasp"), alternate_every=cfg.alternate_every))
            else:
                out.append(replace(b, **common, trainable=("move", "push", "grasp"), coordination="max_q"))
    return out


def run_pipeline(cfg: PipelineConfig, out: str | Path, init: str | None = None, log: Callable[[str], None] = print) -> dict[str, Any]:
    """Run the stages in order; returns ``{stage: summary}`` plus the calibrated Q*_g."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary: dict[str, Any] = {}
    weights = init
    q_star = cfg.base.q_star
    discriminator: str | None = None
    for stage_cfg in stage_configs(cfg):
        name = stage_cfg.env_id.split("-")[1]
        stage_cfg = replace(stage_cfg, q_star=q_star)
        if name in ("Stage3", "Stage4", "Stage5") and discriminator is not None:
            stage_cfg = replace(stage_cfg, discriminator=discriminator)
        stage_dir = out / name
        done = stage_dir / "done.json"
        if done.is_file():
            log(f"{name}: already finished, skipping")
            result = json.loads(done.read_text())
        else:
            log(f"{name}: {stage_cfg.steps} iterations, training {stage_cfg.trainable}, init {weights}")
            learner = Learner(stage_cfg, stage_dir, init=weights, log=log)
            result = learner.run()
            if name == "Stage2":
                # Q*_g: where the Q of successful target grasps settled (paper, Stage II).
                result["q_star"] = learner.calibrated_q_star()
                if not math.isnan(result["q_star"]):
                    learner.policy.set_q_star(result["q_star"])
                    learner.save_state()
            result = json_safe(result)
            done.write_text(json.dumps(result))
        summary[name] = result
        weights = str(stage_dir / "weights.safetensors")
        if name == "Stage2":
            q_star = float(result["q_star"]) if result.get("q_star") is not None else float("nan")
            discriminator = weights
    summary["q_star"] = None if math.isnan(q_star) else q_star
    summary["final_weights"] = weights
    (out / "pipeline.json").write_text(json.dumps(json_safe(summary), indent=1))
    return summary

