"""Q*_g of the grasp-first MPGNet (the previous release's shipped net) calibrated in N-object Stage V scenes, by the training procedure
(``Learner.calibrate_in_scenes``: 50 greedy grasp-only episodes, calibration seeds, no learning).

    python benchmarks/results/grasp_first/calibrate_30objects.py --out /tmp/cal30 --objects 30

Writes ``<out>/calibration.json`` (``calibration_30objects.json`` beside this file is its output).
``--config``, ``--env`` and ``--policy`` calibrate another net with its own settings the same way
(``benchmarks/results/grasp_probe/``: the occluded-curriculum config, ``MPG-Occluded-v0``, 10 objects).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

from mpg_agents import training_stages as ts
from mpg_agents.cli import training_settings
from mpg_agents.learner import Learner

CONFIG = "benchmarks/results/grasp_first/train.toml"  # the settings that net trained with
DISCRIMINATOR = "benchmarks/results/zero_init/Stage2/weights.safetensors"  # its Stage II


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="a fresh folder for the learner's state and calibration.json")
    parser.add_argument("--objects", type=int, default=30)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--policy", default="benchmarks/results/grasp_first/mpgnet_small.safetensors")
    parser.add_argument("--config", default=CONFIG, help="the settings the net trained with")
    parser.add_argument("--env", default="MPG-Stage5-v0", help="the env of the stage whose calibration settings apply")
    args = parser.parse_args()
    base, stages = training_settings(args.config)
    base = replace(base, discriminator=DISCRIMINATOR, seed=0, num_objects=args.objects)
    learner = Learner(base, ts.stage_for_env(args.env, stages), args.out, init=args.policy)
    start = time.perf_counter()
    print(f"Q*_g in the checkpoint: {learner.policy.q_star:.4f}")
    learner.calibrate_in_scenes(args.episodes)
    print(f"{time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
