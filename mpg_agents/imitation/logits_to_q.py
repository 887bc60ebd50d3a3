"""A behaviour-cloning net as the starting Q-network of reinforcement learning.

Behaviour cloning trains MPGNet's maps as the logits of one softmax: only their differences
count, and on the hard track they span about -90 to +20, while the Q-learner's returns lie in
``q_bounds`` (about -1 to 2). Started from those logits as they are, temporal-difference updates
would pull the few actions they visit down to the return scale while every unvisited pixel
kept its logit, and the greedy action would wander to those. So the logits are first mapped
onto the return scale by one affine map shared by every branch (the branches' order, and so
the cloned policy's choices, stay as they were):

    Q = value * (logit - median of all logits) / (median logit of the demonstrated actions - median of all logits)

A typical pixel starts at Q = 0 (a zero-initialised head's value), a demonstrated action at
``value`` (default 1, the return of an action that leads to taking the target). The medians are
measured on the demonstrations the net was cloned from. The map is written into each branch's
last (linear) convolution, so the result is an ordinary MPGNet checkpoint for ``mpg-train --init``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
from torch import nn

from mpg_agents.acting.weights import load_mpgnet_weights, read_checkpoint_header, save_mpgnet
from mpg_agents.imitation.demo_samples import DemoSamples
from mpg_agents.network.mpgnet import MPGNet, flat_q
from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_agents.network.primitive_net import PrimitiveNet


@dataclass(frozen=True)
class LogitAnchors:
    """The two logits the affine map sends to 0 and to ``value``."""

    typical: float  # median of every logit (all primitives, rotations and pixels), over the samples
    demonstrated: float  # median logit of the demonstrated actions
    samples: int

    def scale_offset(self, value: float = 1.0) -> tuple[float, float]:
        """``(a, b)`` with ``Q = a * logit + b``.

        Raises:
            ValueError: when the demonstrated actions do not stand above the typical logit (a net
                that did not learn to prefer them has no scale to take).
        """
        spread = self.demonstrated - self.typical
        if not spread > 0:
            raise ValueError(
                f"the demonstrated actions' median logit ({self.demonstrated:.3f}) is not above the median logit "
                f"({self.typical:.3f}): the net has not learned to prefer them, so its logits give no Q scale"
            )
        scale = value / spread
        return scale, -self.typical * scale


def affine_map(typical: float, demonstrated: float, value: float = 1.0) -> tuple[float, float]:
    """``(a, b)`` sending ``typical`` to 0 and ``demonstrated`` to ``value`` (pure; see :class:`LogitAnchors`)."""
    return LogitAnchors(typical, demonstrated, 0).scale_offset(value)


@torch.no_grad()
def measure_anchors(
    net: MPGNet, samples: DemoSamples, primitives: Sequence[str], indices: Sequence[int] | np.ndarray
) -> LogitAnchors:
    """The medians of :class:`LogitAnchors` over the demonstrations at ``indices`` (one forward
    pass each, every rotation, in eval mode)."""
    net.eval()
    typical, demonstrated = [], []
    for i in indices:
        obs, action = samples.batch([int(i)])
        logits = flat_q(net({k: torch.from_numpy(v) for k, v in obs.items()}, tuple(primitives)), tuple(primitives))[0]
        typical.append(float(logits.median()))
        demonstrated.append(float(logits[int(action[0])]))
    return LogitAnchors(float(np.median(typical)), float(np.median(demonstrated)), len(typical))


@torch.no_grad()
def rescale_heads(net: MPGNet, scale: float, offset: float) -> None:
    """Make every branch answer ``scale * map + offset``: its head's last convolution is linear,
    and what follows it (upsampling to the heightmap) keeps an affine map."""
    if not scale > 0:
        raise ValueError(f"scale must be > 0 (a negative one would reverse the policy), got {scale}")
    for name, branch in net.branches.items():
        last = cast(PrimitiveNet, branch).head[-1]
        if not isinstance(last, nn.Conv2d) or last.bias is None:
            raise ValueError(f"branch {name!r}: its head does not end in a biased convolution")
        last.weight.mul_(scale)
        last.bias.mul_(scale).add_(offset)


def logits_to_q(src: str | Path, demos: str | Path, dst: str | Path, samples: int = 64, value: float = 1.0) -> dict[str, Any]:
    """Write ``dst``: the behaviour-cloning checkpoint ``src`` with its logits mapped onto the
    return scale, anchored on up to ``samples`` demonstrations of the dataset ``demos`` (evenly
    spread over the episodes the net was cloned from: the dataset's first ``demo_episodes``). Returns what was measured
    and applied (also written in ``dst``'s header as ``logits_to_q``).

    Raises:
        ValueError: ``src`` is not a behaviour-cloning checkpoint (or is one already mapped),
            ``demos`` is not the dataset it was cloned from, ``samples`` or ``value`` is not
            positive, or the net gives no scale (:meth:`LogitAnchors.scale_offset`).
    """
    if samples < 1:
        raise ValueError(f"samples must be >= 1, got {samples}")
    if not value > 0:
        raise ValueError(f"value must be > 0, got {value}")
    header = read_checkpoint_header(src)
    extra = header.get("extra", {})
    if "imitation" not in extra:
        raise ValueError(f"{src} is not a behaviour-cloning checkpoint (mpg-train --baseline bc writes one)")
    if "logits_to_q" in extra:
        raise ValueError(f"{src} is already mapped onto the return scale (by mpg-bc-to-q); map the cloned net itself")
    config = MPGNetConfig.from_checkpoint(header["config"])
    # The raw maps are all it reads: no finger masks (they need an env's gripper geometry).
    net = MPGNet(MPGNetConfig.from_checkpoint(header["config"], grasp_fingers="any", move_fingers="any"))
    load_mpgnet_weights(net, src)
    card = extra["imitation"]
    data = DemoSamples(demos, int(card["demo_episodes"]))  # the episodes it was cloned from
    cloned_from = card["dataset"]["digest"]
    if data.source.digest != cloned_from:
        raise ValueError(
            f"--demos {str(demos)!r} is not the dataset {src} was cloned from (its digest {data.source.digest[:12]}..., "
            f"the net's {cloned_from[:12]}...: {card['dataset']['folder']})"
        )
    primitives = tuple(data.action_primitives)
    indices = np.unique(np.linspace(0, len(data) - 1, min(samples, len(data))).round().astype(np.int64))
    anchors = measure_anchors(net, data, primitives, indices)
    scale, offset = anchors.scale_offset(value)
    rescale_heads(net, scale, offset)
    record = {
        "source": str(src),
        "demos_digest": data.source.digest,
        "samples": anchors.samples,
        "median_logit": anchors.typical,
        "median_demonstrated_logit": anchors.demonstrated,
        "value": value,
        "scale": scale,
        "offset": offset,
    }
    save_mpgnet(net, dst, extra={**extra, "logits_to_q": record}, config=config)
    return record


def main(argv: Sequence[str] | None = None) -> int:
    """``mpg-bc-to-q SRC DST --demos DIR [--samples N] [--value V]``: a behaviour-cloning
    checkpoint as the starting Q-network of ``mpg-train --init``; the exit status."""
    import argparse  # noqa: PLC0415
    import json  # noqa: PLC0415

    from mpg_agents.cli_input import UsageError, check_output, fail  # noqa: PLC0415
    from mpg_envs.files import WriteFailed  # noqa: PLC0415

    parser = argparse.ArgumentParser(
        prog="mpg-bc-to-q",
        description="Map a behaviour-cloning net's logits onto the return scale (one affine map for every branch: the "
        "median logit -> 0, the demonstrated actions' median logit -> VALUE), so reinforcement learning can start "
        "from it: mpg-train --init DST.",
    )
    parser.add_argument("src", help="the behaviour-cloning checkpoint (mpg-train --baseline bc: RUN/weights.safetensors)")
    parser.add_argument("dst", help="the starting checkpoint to write")
    parser.add_argument("--demos", required=True, help="the dataset the net was cloned from (mpg-demos --out DIR)")
    parser.add_argument("--samples", type=int, default=64, help="demonstrations the medians are measured on (default 64)")
    parser.add_argument("--value", type=float, default=1.0, help="the Q of a demonstrated action (default 1)")
    args = parser.parse_args(argv)
    try:
        check_output(args.dst, "dst", {"the source checkpoint": args.src})
        record = logits_to_q(args.src, args.demos, args.dst, samples=args.samples, value=args.value)
    except ImportError as exc:  # Minari, the demos extra
        return fail(UsageError(str(exc)))
    except (UsageError, FileNotFoundError, ValueError, WriteFailed) as exc:
        return fail(exc)
    print(json.dumps(record))
    return 0
