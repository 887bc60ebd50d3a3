"""The TD step gives what it gave before the batch was vectorised (the rotations resampled in
one call, the trunks run on the whole batch off the CPU): loss, per-sample surprise and every
parameter's gradient, on recorded batches, up to floating-point tolerance.

Gradients, not parameters after the Adam step, are compared: Adam divides by the gradient's own
running size, so a gradient at rounding level (a bias in front of a batch norm) moves its
parameter by the full learning rate in a direction that depends on the CPU's summation order.
Each gradient's tolerance scales with its tensor's size and the step's mean gradient.

``data/td_step_reference.json`` was written by :func:`reference_record` with the code as it was
before (``python tests/agents/test_td_step_reference.py OUT`` run on that checkout, 2 threads).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from mpg_envs.grid.actions import PixelActionSpace, encode_action

try:
    from .fake_env import observation_space, random_scene
except ImportError:  # run as a script on another checkout
    from tests.agents.fake_env import observation_space, random_scene

FIXTURE = Path(__file__).parent / "data" / "td_step_reference.json"
PRIMS = ("move", "push", "grasp")
NET = {"trunk_depth": 2, "grasp_region": "target", "target_margin_px": -8}


def recorded_batch(size: int, seed: int) -> SimpleNamespace:
    """``size`` transitions of synthetic scenes (one terminal), every primitive."""
    rng = np.random.default_rng(seed)
    obs, nxt, actions = [], [], []
    for t in range(size):
        o, n = random_scene(rng), random_scene(rng)
        rows, cols = np.nonzero(o["mask"])
        k = int(rng.integers(len(rows)))
        actions.append(encode_action(PRIMS, PRIMS[t % 3], int(rng.integers(16)), int(rows[k]), int(cols[k])))
        obs.append(o)
        nxt.append(n)
    stack = lambda items: {key: torch.as_tensor(np.stack([i[key] for i in items])) for key in items[0]}  # noqa: E731
    return SimpleNamespace(
        observations=stack(obs), next_observations=stack(nxt), actions=torch.tensor(actions).reshape(-1, 1),
        rewards=torch.as_tensor(rng.uniform(-0.5, 1.0, (size, 1)), dtype=torch.float32),
        dones=torch.tensor([[1.0]] + [[0.0]] * (size - 1)),
    )


def reference_record(steps: int = 2, size: int = 3, trunk_batch: int | str | None = 4) -> dict:
    """Two TD steps of a seeded small net on recorded batches: losses, surprises and, per step,
    each parameter's gradient sum and absolute sum (``trunk_batch``: the inference chunk of the
    trunks; ``None`` runs them as an accelerator does)."""
    from mpg_agents.acting.agent import MPGAgent
    from mpg_agents.acting.q_function import MPGQFunction
    from mpg_agents.learning.td_step import TDStepConfig, td_step
    from mpg_agents.network.mpgnet import recompute_batch_norm_statistics

    torch.manual_seed(0)
    net = dict(NET) if trunk_batch == "absent" else {**NET, "trunk_batch": trunk_batch}  # "absent": code before the option
    agent = MPGAgent.build(observation_space(), PixelActionSpace(PRIMS), net_config=net)
    first = recorded_batch(size, 100)
    recompute_batch_norm_statistics(agent.q_net, agent.q_net, first.observations)  # no denormal eval-mode activations
    target = MPGQFunction(agent.net_config, agent.action_primitives)
    target.load_state_dict(agent.q_net.state_dict())
    target.set_training_mode(False)
    optimizer = torch.optim.Adam(agent.q_net.parameters(), lr=1e-3)
    config = TDStepConfig(gamma=0.5, target_bounds=(-1.0, 2.0))
    record: dict = {"loss": [], "surprise": [], "gradients": []}
    for step in range(steps):
        result = td_step(agent.q_net, target, optimizer, recorded_batch(size, 100 + step), config)
        record["loss"].append(result.loss)
        record["surprise"].append(result.surprise.tolist())
        record["gradients"].append({
            name: [float(p.grad.double().sum()), float(p.grad.double().abs().sum()), p.grad.numel()]
            for name, p in agent.q_net.named_parameters() if p.grad is not None
        })
    return record


@pytest.mark.parametrize("trunk_batch", [4, None])
def test_the_batched_step_gives_todays_result(trunk_batch):
    expected = json.loads(FIXTURE.read_text())
    got = reference_record(trunk_batch=trunk_batch)
    assert got["loss"] == pytest.approx(expected["loss"], rel=1e-3, abs=1e-6)
    for g, e in zip(got["surprise"], expected["surprise"], strict=True):
        assert g == pytest.approx(e, rel=1e-3, abs=1e-6)
    for got_step, expected_step in zip(got["gradients"], expected["gradients"], strict=True):
        assert got_step.keys() == expected_step.keys()
        mean = sum(a for _, a, _ in expected_step.values()) / sum(n for _, _, n in expected_step.values())
        for name, (total, abs_total, count) in expected_step.items():
            tolerance = 1e-3 * abs_total + 1e-4 * mean * count
            assert got_step[name][0] == pytest.approx(total, abs=tolerance), name
            assert got_step[name][1] == pytest.approx(abs_total, abs=tolerance), name


if __name__ == "__main__":
    torch.set_num_threads(2)  # as tests/agents/conftest.py runs the tests
    Path(sys.argv[1]).write_text(json.dumps(reference_record(trunk_batch="absent"), indent=1))
