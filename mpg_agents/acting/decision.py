"""The greedy coordinated decision: which primitive, then its best pixel and rotation.

The primitive comes from :func:`mpg_agents.acting.coordination.choose_primitive` (the occlusion bit,
Q*_g and the best Q of the primitives the rule asks about); only the branches the rule needs
are computed. Then the best action of that primitive's Q maps is taken where it may act
(:meth:`mpg_agents.network.mpgnet.MPGNet.actable`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

import torch
from torch import Tensor

from mpg_agents.acting.coordination import choose_primitive
from mpg_agents.acting.q_function import MPGQFunction, mask_outside
from mpg_agents.network.mpgnet import EncodedObs, MPGNet
from mpg_agents.network.regions import region_max
from mpg_envs.grid.actions import encode_action
from mpg_envs.grid.primitive_specs import GRASP


class Decision(NamedTuple):
    """One coordinated decision: the flat action and what it was made from."""

    action: int
    primitive: str
    rotation: int
    row: int
    col: int
    q_value: float
    grasp_score: float  # best grasp Q in the target region, NaN when the grasp net was not run
    q_maps: dict[str, Tensor]  # the (R, H, W) maps computed for this decision


def decide(
    q: MPGQFunction,
    obs: Mapping[str, Tensor],
    coordination: str,
    q_star: float | None,
    primitive: str | None = None,
    forbidden: Mapping[str, Tensor] | None = None,
) -> list[Decision]:
    """Coordinated decisions for a batch of observation tensors, one per sample.

    Args:
        q: the network on the env's action space.
        obs: a batch (leading axis) of raw observation tensors.
        coordination: one of :data:`~mpg_agents.acting.coordination.COORDINATIONS`.
        q_star: Q*_g (``None``: none yet).
        primitive: overrides the coordination's choice of primitive (e.g. Stage IV's final grasp).
        forbidden: ``{primitive: (R, H, W) bool}`` actions not to take (one sample only; e.g.
            actions that already failed on this unchanged scene).

    Raises:
        ValueError: ``forbidden`` with a batch of more than one, or a ``primitive`` the network
            cannot use here.
    """
    batch = batch_size(obs)
    if forbidden and batch != 1:
        raise ValueError(f"forbidden actions apply to one observation, got a batch of {batch}")
    decisions = []
    for i in range(batch):
        single = {k: v[i : i + 1] for k, v in obs.items()}
        decisions.append(_decide_one(q, q.mpgnet.encode(single), coordination, q_star, primitive, forbidden))
    return decisions


def _decide_one(
    q: MPGQFunction,
    enc: EncodedObs,
    coordination: str,
    q_star: float | None,
    primitive: str | None,
    forbidden: Mapping[str, Tensor] | None,
) -> Decision:
    net = q.mpgnet
    maps: dict[str, Tensor] = {}
    actable: dict[str, Tensor] = {}

    def run(p: str) -> Tensor:
        """``p``'s ``(R, H, W)`` Q maps, -inf where it may not act (each branch run once)."""
        if p not in maps:
            maps[p], actable[p] = _maps_and_actable(net, enc, p)
            if forbidden is not None and p in forbidden:
                barred = torch.as_tensor(forbidden[p], dtype=torch.bool, device=actable[p].device)
                kept = actable[p].masked_fill(barred, float("-inf"))
                if bool(torch.isfinite(kept).any()):  # never bar every action: the best of them is still an action
                    actable[p] = kept
        return actable[p]

    if primitive is not None:
        if primitive not in q.usable_primitives:
            raise ValueError(f"primitive {primitive!r} is not allowed here; allowed: {q.usable_primitives}")
    else:
        occluded = bool(enc.occluded[0]) if enc.occluded is not None else False
        best = lambda p: float(run(p).max())  # noqa: E731
        primitive = choose_primitive(coordination, q.usable_primitives, occluded, q_star, best)
    chosen = run(primitive)
    flat = int(chosen.flatten().argmax())
    value = float(chosen.flatten()[flat])
    rot, rest = divmod(flat, chosen.shape[1] * chosen.shape[2])
    row, col = divmod(rest, chosen.shape[2])
    grasp_score = float(region_max(maps[GRASP][None], net.grasp_where(enc))[0]) if GRASP in maps else float("nan")
    action = encode_action(q.action_primitives, primitive, rot, row, col, size=q.net_config.heightmap_size)
    return Decision(action, primitive, rot, row, col, value, grasp_score, maps)


def _maps_and_actable(net: MPGNet, enc: EncodedObs, primitive: str) -> tuple[Tensor, Tensor]:
    """``primitive``'s ``(R, H, W)`` Q maps of the first observation in ``enc``, and the same maps
    with -inf where it may not act (:meth:`~mpg_agents.network.mpgnet.MPGNet.actable`)."""
    maps = net.maps_from(enc, (primitive,))[primitive][0]
    allowed = net.actable(enc, primitive)
    return maps, mask_outside(maps, None if allowed is None else allowed[0])


def batch_size(obs: Mapping[str, Tensor]) -> int:
    """The leading axis of a batch of observation tensors."""
    return int(next(iter(obs.values())).shape[0])


def spaced_best(q_map: Tensor, k: int, spacing_px: float, taken: tuple[int, int] | None = None) -> list[tuple[int, int, int]]:
    """The ``k`` best ``(rotation, row, col)`` of a ``(R, H, W)`` Q map at pixels at least
    ``spacing_px`` apart (and that far from the ``taken`` ``(row, col)``), each at its best
    rotation; ``-inf`` entries are never chosen, so fewer than ``k`` may come back.

    Greedy suppression: the best pixel, then the best outside a disc of radius ``spacing_px``
    around every pixel chosen so far. Alternatives spread over the scene label places the
    taken action did not try, where the next-best entries of a Q map sit beside the best.

    Raises:
        ValueError: ``q_map`` not three-dimensional, ``k`` negative or ``spacing_px`` negative.
    """
    if q_map.dim() != 3:
        raise ValueError(f"q_map must be (R, H, W), got shape {tuple(q_map.shape)}")
    if k < 0 or spacing_px < 0:
        raise ValueError(f"k and spacing_px must be >= 0, got k={k}, spacing_px={spacing_px}")
    best, rotation = q_map.max(dim=0)  # a new tensor: suppression writes into it, not into q_map
    rows = torch.arange(best.shape[0], device=best.device)[:, None]
    cols = torch.arange(best.shape[1], device=best.device)[None, :]

    def suppress(row: int, col: int) -> None:
        near = (rows - row) ** 2 + (cols - col) ** 2 < spacing_px**2
        best.masked_fill_(near, float("-inf"))

    if taken is not None:
        suppress(*taken)
    chosen: list[tuple[int, int, int]] = []
    while len(chosen) < k:
        flat = int(best.flatten().argmax())
        row, col = divmod(flat, best.shape[1])
        if not bool(torch.isfinite(best[row, col])):
            break
        chosen.append((int(rotation[row, col]), row, col))
        suppress(row, col)
        best[row, col] = float("-inf")  # spacing 0 still never repeats a pixel
    return chosen


def alternatives(
    q: MPGQFunction, obs: Mapping[str, Tensor], primitive: str, k: int, spacing_px: float, taken: tuple[int, int] | None = None
) -> list[int]:
    """The flat actions of :func:`spaced_best` over ``primitive``'s Q maps where it may act, for
    one observation tensor batch of one, away from the ``taken`` ``(row, col)`` (if any).

    Raises:
        ValueError: a batch of several observations.
    """
    if batch_size(obs) != 1:
        raise ValueError(f"alternatives are for one observation, got a batch of {batch_size(obs)}")
    _, actable = _maps_and_actable(q.mpgnet, q.mpgnet.encode(obs), primitive)
    size = q.net_config.heightmap_size
    spots = spaced_best(actable, k, spacing_px, taken=taken)
    return [encode_action(q.action_primitives, primitive, r, row, col, size=size) for r, row, col in spots]
