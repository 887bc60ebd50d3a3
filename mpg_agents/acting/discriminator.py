"""The discriminator: a fixed grasp net that scores states for the move and push rewards.

Stages III-V hand it to the envs as their ``grasp_scorer`` (the paper's discriminator: the
Stage II grasp net, frozen).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from mpg_agents.acting.weights import load_mpgnet
from mpg_agents.network.finger_geometry import FingerGeometry
from mpg_agents.network.mpgnet import MPGNet
from mpg_envs.grid.primitive_specs import GRASP


class Discriminator:
    """``callable(obs) -> float``: the best grasp Q where a grasp may act (for the envs).

    Runs the grasp branch in eval mode without gradients and restores the network's mode.
    """

    def __init__(self, net: MPGNet) -> None:
        if GRASP not in net.primitives:
            raise ValueError(f"the discriminator needs a grasp branch; this MPGNet has {net.primitives}")
        self.net = net

    @classmethod
    def from_weights(
        cls, path: str | Path, geometry: FingerGeometry | None = None, device: torch.device | str = "cpu"
    ) -> Discriminator:
        """A discriminator from a saved MPGNet (e.g. the Stage II grasp net) on ``device``;
        ``geometry``: the grasp geometry of the envs it scores for (default: the default env's)."""
        net, _ = load_mpgnet(path, primitives=(GRASP,), geometry=geometry)
        return cls(net.to(device))

    def __call__(self, obs: Mapping[str, Any]) -> float:
        was_training = self.net.training
        self.net.eval()
        try:
            with torch.inference_mode():
                return float(self.net.grasp_score(obs)[0])
        finally:
            self.net.train(was_training)
