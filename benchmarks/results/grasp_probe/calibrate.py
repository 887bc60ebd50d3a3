"""Q*_g of the grasp probe (benchmarks/results/grasp_probe/) calibrated by the pipeline's procedure:
``Learner.calibrate_in_scenes``, 50 greedy grasp-only episodes in 10-object MPG-Occluded-v0
calibration scenes (the shipped Stage V's settings: lower quartile), no learning.

    python benchmarks/results/grasp_probe/calibrate.py

Writes ``runs/cal_probe/calibration.json`` (``calibration.json`` beside this file is its output).
"""

from dataclasses import replace

from mpg_agents import training_stages as ts
from mpg_agents.cli import training_settings
from mpg_agents.learner import Learner

base, stages = training_settings("benchmarks/results/occluded_curriculum/train.toml")
base = replace(base, discriminator="benchmarks/results/zero_init/Stage2/weights.safetensors", seed=0, num_objects=10)
learner = Learner(base, ts.stage_for_env("MPG-Occluded-v0", stages), "runs/cal_probe",
                  init="benchmarks/results/grasp_probe/weights.safetensors")
print(f"Q*_g in the checkpoint: {learner.policy.q_star:.4f}")
learner.calibrate_in_scenes(50)
print(f"calibrated: {learner.policy.q_star:.4f}")
