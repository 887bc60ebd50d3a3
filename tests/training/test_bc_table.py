"""benchmarks/bc_table.py: the behaviour-cloning table and plot from run folders, checked by hand."""

from __future__ import annotations

import json

import pytest
import torch

from mpg_agents.acting.weights import save_mpgnet
from mpg_agents.imitation.bc_config import BCConfig, bc_net_config
from mpg_agents.network.mpgnet import MPGNet


def _run(folder, demos: int, success: float, interval, motions: float) -> None:
    folder.mkdir(parents=True)
    torch.manual_seed(0)
    net = MPGNet(bc_net_config(BCConfig(), ("grasp",)))
    card = {
        "imitation": {
            "demo_episodes": demos,
            "dataset": {"samples": 2 * demos, "env_id": "MPG-Stage2-v0", "env_kwargs": {"num_objects": 10}},
            "steps": 300,
            "wall_time_s": 600.0,
            "rotations_per_sample": 4,
            "quarter_turns": True,
        }
    }
    save_mpgnet(net, folder / "weights.safetensors", extra=card)
    held = {
        "env_id": "MPG-Stage2-v0",
        "num_objects": 10,
        "episodes": 100,
        "seed": 500000,
        "task_success_rate": success,
        "success_interval": interval,
        "average_motions": motions,
        "mispicks_per_episode": 0.25,
        "versions": {"mujoco": "3.17.0"},
    }
    (folder / "heldout.json").write_text(json.dumps(held))
    (folder / "bc_progress.csv").write_text(
        "step,loss,accuracy,step_s,wall_s\n1,9.0,0.0,1.5,1.5\n2,8.0,0.0,0.5,2.0\n3,7.0,0.0,1.0,3.0\n"
    )


def test_one_row_per_run_ordered_by_demonstrations_and_a_plot(benchmark_script, tmp_path, capsys):
    script = benchmark_script("bc_table")
    _run(tmp_path / "stage2" / "bc100", 100, 0.62, [0.52, 0.71], 3.5)
    _run(tmp_path / "stage2" / "bc10", 10, 0.2, [0.13, 0.29], 6.25)
    own_eval = json.loads((tmp_path / "stage2" / "bc100" / "heldout.json").read_text())
    on_4 = {**own_eval, "task_success_rate": 0.7, "success_interval": [0.6, 0.78], "versions": {"mujoco": "4.0.0"}}
    (tmp_path / "stage2" / "bc100" / "heldout_mujoco4.json").write_text(json.dumps(on_4))  # its own track on MuJoCo 4
    unseen = json.loads((tmp_path / "stage2" / "bc100" / "heldout.json").read_text())
    unseen.update(env_id="MPG-OccludedHardNovel-v0", num_objects=15, task_success_rate=0.3, success_interval=[0.22, 0.4])
    (tmp_path / "stage2" / "bc100" / "heldout_unseen.json").write_text(json.dumps(unseen))  # the same policy elsewhere
    plot = tmp_path / "plot.png"
    assert script.main(["--results", str(tmp_path), "--plot", str(plot)]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("| MPG-Stage2-v0")]
    own = "| MPG-Stage2-v0 (10 objects) | MPG-Stage2-v0 (10 objects) | 3.17.0 |"
    assert rows == [
        f"{own} 10 (20) | 300 | 1.00 | 10 | 20% [13, 29] of 100 | 6.25 | 0.25 |",
        f"{own} 100 (200) | 300 | 1.00 | 10 | 62% [52, 71] of 100 | 3.50 | 0.25 |",
        f"{own.replace('3.17.0', '4.0.0')} 100 (200) | 300 | 1.00 | 10 | 70% [60, 78] of 100 | 3.50 | 0.25 |",
    ]
    transfer = [line for line in out.splitlines() if line.startswith("| MPG-OccludedHardNovel-v0")]
    copied = "| MPG-OccludedHardNovel-v0 (15 objects) | MPG-Stage2-v0 (10 objects) | 3.17.0 |"
    assert transfer == [f"{copied} 100 (200) | 300 | 1.00 | 10 | 30% [22, 40] of 100 | 3.50 | 0.25 |"]
    assert "4 rotations per sample, quarter turns on; held-out seeds from 500000" in out
    assert plot.stat().st_size > 1000


def test_a_run_without_its_evaluation_is_named(benchmark_script, tmp_path, capsys):
    script = benchmark_script("bc_table")
    _run(tmp_path / "hard" / "bc10", 10, 0.2, [0.13, 0.29], 6.25)
    (tmp_path / "hard" / "bc10" / "heldout.json").unlink()
    with pytest.raises(FileNotFoundError, match=r"bc10 has weights.safetensors but no heldout.json"):
        script.main(["--results", str(tmp_path)])
    assert script.main(["--results", str(tmp_path / "none")]) == 1
    assert "no behaviour-cloning runs" in capsys.readouterr().err
