"""The trained locator as a policy uses it: a weights file, its thresholds, ``locate(obs)``.

The weights file is safetensors with one JSON header (``mpg_locator``): the network's
config, the pixel threshold, the "seen" threshold calibrated on tuning samples, the search
rule chosen on tuning episodes (:class:`~mpg_agents.locator.cover.CoverRule`) and the
training record the model card is written from. Nothing is unpickled.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors import safe_open
from safetensors.torch import load_file, save

from mpg_agents.locator.cover import CoverRule
from mpg_agents.locator.features import RESOLUTION, Exemplar, exemplar_blobs, scene_input
from mpg_agents.locator.net import LocatorConfig, LocatorNet
from mpg_agents.locator.template import (
    component_of,
    component_parts,
    fit_template,
    grow_by_fit,
    pick_candidate,
    rated_parts,
)
from mpg_envs.files import write_bytes_whole
from mpg_envs.perception.exemplar_match import (
    Blob,
    MatchSettings,
    colour_gap,
    footprint_sides,
    heights,
    lab_colours,
    pose_fit,
)

HEADER_KEY = "mpg_locator"
SHIPPED_LOCATOR = Path(__file__).resolve().parent.parent / "checkpoints" / "locator.safetensors"
"""The shipped locator's weights (trained by ``mpg-train-locator``; model card beside it)."""


@dataclass(frozen=True)
class Location:
    """Where the exemplar's object shows: ``probability`` per pixel (H x W, float32), ``mask``
    (its pixels above the threshold, uint8), ``seen`` (whether it shows at all), the
    ``seen_probability`` that decided it and, by the ``"template"`` snapping, the chosen object's
    ``fit`` to the exemplar (``None`` otherwise)."""

    probability: np.ndarray
    mask: np.ndarray
    seen: bool
    seen_probability: float
    fit: float | None = None


SNAPS = ("off", "probability", "shape", "pose", "template")
"""How the located mask snaps to the exemplar matcher's blobs: not at all; to the blob whose
pixels the network rates highest; to the blob whose mean probability times its shape score
(:func:`~mpg_envs.perception.exemplar_match.shape_score`) is highest; as the last, but an
uncovered blob (its whole top shows) is weighed by how well it shows the exemplar's box in some
pose, leaning ones included (:func:`~mpg_envs.perception.exemplar_match.pose_fit`), and one that
fits no pose by at least the locator's ``pose_floor`` is not the target (see :func:`blob_weights`);
to the blob the network rates highest, an uncovered one that fits the exemplar's heights turned to
any yaw worse than the locator's ``min_fit`` weighed down, grown over its object's rated blobs
(:func:`template_mask`)."""
COMPONENT_MIN_HEIGHT = 0.005
"""Metres above the table a pixel of the exemplar's colour stands to be part of an object by the
``"template"`` snapping (lower than the matcher's 1 cm: a flat object's rim stays on it)."""
MISFIT_WEIGHT = 0.1
"""The ``"template"`` snapping weighs an uncovered blob that fits the exemplar worse than the
locator's ``min_fit`` by this share of its probability."""
PART_SHARE = 0.1
"""The ``"template"`` snapping grows the chosen blob over its object's blobs rated at least this
share of its best-rated blob."""
GROWTHS = ("rated", "fit")
"""How the ``"template"`` snapping grows the chosen blob over the other blobs of the object of
the exemplar's colour it lies in (rated at least :data:`PART_SHARE` of its best): over all of them
(an object of that colour touching the target comes with it), or over each whose addition leaves
the grown object fitting the exemplar at least as well (:func:`~mpg_agents.locator.template.grow_by_fit`)."""


def template_mask(
    probability: np.ndarray,
    obs: Mapping[str, np.ndarray],
    exemplar: Exemplar,
    gap: np.ndarray,
    blobs: list[Blob],
    min_fit: float = 0.5,
    grow: str = "rated",
) -> tuple[np.ndarray, float] | None:
    """The ``"template"`` snapping's mask (bool) for the located ``probability`` of ``obs``, with
    the chosen blob's fit: of the matcher's ``blobs``, the one whose mean probability is highest,
    an uncovered blob (its whole top shows) that fits the exemplar's heights worse than
    ``min_fit`` (:func:`~mpg_agents.locator.template.fit_template`) weighed down to
    :data:`MISFIT_WEIGHT` of its probability (a look-alike of another shape in full view; taken
    still when nothing else rates higher: the target may rest in another pose); grown over the
    object of the exemplar's colour it lies in (:func:`~mpg_agents.locator.template.component_of`,
    ``gap`` the scene's colour gap to it) by that object's blobs rated at least
    :data:`PART_SHARE` of its best, by the growth ``grow`` (one of :data:`GROWTHS`).
    ``None`` when no blob is of its colour. ``ValueError`` when ``grow`` is not one of :data:`GROWTHS`."""
    if grow not in GROWTHS:
        raise ValueError(f"grow must be one of {GROWTHS}, got {grow!r}")
    settings = MatchSettings()
    up = heights(obs["depth"], settings)
    template = exemplar.template
    fits: dict[int, float] = {}

    def weight(k: int) -> float:
        fits[k] = fit_template(template, up, blobs[k].pixels, covered=blobs[k].covered)
        return 1.0 if blobs[k].covered or fits[k] >= min_fit else MISFIT_WEIGHT

    pixels = [b.pixels for b in blobs]
    best = pick_candidate(probability, pixels, weight)
    if best is None:
        return None
    chosen = blobs[best].pixels
    home = component_of(chosen, gap, up, settings.colour_distance, COMPONENT_MIN_HEIGHT, settings.min_pixels)
    if home is None:
        return chosen, fits[best]
    if grow == "rated":
        return component_parts(probability, home, pixels, PART_SHARE) | chosen, fits[best]
    parts = [k for k in rated_parts(probability, home, pixels, PART_SHARE) if k != best]

    def grown_fit(grown: np.ndarray, covered: bool) -> float:
        return fit_template(template, up, grown, covered=covered)

    grown = grow_by_fit(
        chosen, blobs[best].covered, fits[best], [(blobs[k].pixels, blobs[k].covered) for k in parts], grown_fit
    )
    return grown, fits[best]


def blob_weights(
    snap: str, blobs: list[Blob], exemplar: Exemplar, pose_floor: float
) -> tuple[list[float] | None, np.ndarray | None]:
    """``(weights, ruled_out)`` of the matcher's ``blobs`` by the snapping ``snap`` (one of
    :data:`SNAPS`): the weights :func:`snap_to_blob` takes (``None``: all alike) and, by the
    ``"pose"`` snapping, the pixels of the blobs ruled out (uncovered, fitting no pose of the
    exemplar's box by ``pose_floor``: weight 0; ``None`` otherwise)."""
    if snap == "shape":
        return [b.score for b in blobs], None
    if snap != "pose" or exemplar.poses is None or not blobs:
        return None, None
    weights, ruled_out = [], np.zeros(blobs[0].pixels.shape, bool)
    for blob in blobs:
        if blob.covered:  # part of its top shows: judged as the matcher judges a part
            weights.append(blob.score)
            continue
        fit = pose_fit(footprint_sides(blob.pixels, RESOLUTION), blob.height, exemplar.poses)
        weights.append(fit if fit >= pose_floor else 0.0)
        if fit < pose_floor:
            ruled_out |= blob.pixels
    return weights, ruled_out


def snap_to_blob(
    probability: np.ndarray, blobs: list[np.ndarray], threshold: float, weights: list[float] | None = None
) -> np.ndarray | None:
    """Of ``blobs`` (bool images: the exemplar matcher's blobs of the exemplar's colour), the one
    whose pixels' mean ``probability`` times its weight (``weights``, default 1 each) is highest,
    when that mean reaches ``threshold`` and the product is positive (uint8); else ``None``. The
    network (with the matcher's shape score as weight) chooses the object, the blob gives its
    outline."""
    if not blobs:
        return None
    weights = [1.0] * len(blobs) if weights is None else weights
    if len(weights) != len(blobs):
        raise ValueError(f"snap_to_blob: {len(weights)} weights for {len(blobs)} blobs")
    means = [float(np.asarray(probability)[b].mean()) if b.any() else 0.0 for b in blobs]
    values = [m * w for m, w in zip(means, weights)]
    best = int(np.argmax(values))
    return blobs[best].astype(np.uint8) if means[best] >= threshold and values[best] > 0 else None


def save_locator(
    net: LocatorNet,
    path: str | Path,
    threshold: float,
    seen_threshold: float,
    record: Mapping[str, Any],
    rule: CoverRule | None = None,
    snap: str = "off",
    pose_floor: float = 0.1,
    min_fit: float = 0.0,
    grow: str = "rated",
) -> None:
    """Write ``net`` with its thresholds, search ``rule``, how it snaps to blobs (``snap``,
    ``pose_floor``, ``min_fit``, ``grow``) and training ``record`` to ``path`` (whole or not at all)."""
    header = {
        "config": net.config.to_dict(),
        "threshold": float(threshold),
        "seen_threshold": float(seen_threshold),
        "snap": snap,
        "pose_floor": float(pose_floor),
        "min_fit": float(min_fit),
        "grow": grow,
        "rule": (CoverRule() if rule is None else rule).to_dict(),
        "record": dict(record),
    }
    tensors = {k: v.detach().contiguous().float() for k, v in net.state_dict().items()}
    for name, value in tensors.items():
        if not torch.isfinite(value).all():
            raise ValueError(f"locator tensor {name!r} holds NaN or infinite values: not saved")
    write_bytes_whole(Path(path), save(tensors, metadata={HEADER_KEY: json.dumps(header)}))


def read_locator_header(path: str | Path) -> dict[str, Any]:
    """The header of a locator weights file; ``ValueError`` when ``path`` is not one."""
    with safe_open(str(path), framework="pt") as handle:
        metadata = handle.metadata() or {}
    if HEADER_KEY not in metadata:
        raise ValueError(f"{path} is not a locator weights file (no {HEADER_KEY!r} header)")
    return json.loads(metadata[HEADER_KEY])


class TargetLocator:
    """A trained locator: ``locate(obs)`` for an exemplar-mode observation (one thread's worth
    of work: a few tens of milliseconds on one CPU core); ``rule`` is how a policy using it
    judges cover and searches (:class:`~mpg_agents.locator.cover.CoverRule`); ``snap`` (one
    of :data:`SNAPS`) whether the mask snaps to one of the matcher's blobs (:func:`snap_to_blob`),
    ``pose_floor`` the least pose fit of an uncovered blob by the ``"pose"`` snapping, ``min_fit``
    the least :func:`~mpg_agents.locator.template.fit_template` of an uncovered blob by the
    ``"template"`` snapping (one that fits worse keeps :data:`MISFIT_WEIGHT` of its rating, and
    :class:`~mpg_agents.locator.finding_policy.FindingPolicy` takes it as covered the first
    ``rule.misfit_motions`` times in an episode), ``grow`` how it grows the chosen blob over its
    object (one of :data:`GROWTHS`).

    Raises:
        ValueError: ``snap`` or ``grow`` is not one of :data:`SNAPS` or :data:`GROWTHS`, or
            ``pose_floor`` or ``min_fit`` is outside [0, 1].
    """

    def __init__(
        self,
        net: LocatorNet,
        threshold: float = 0.5,
        seen_threshold: float = 0.5,
        record: Mapping[str, Any] | None = None,
        rule: CoverRule | None = None,
        snap: str = "off",
        pose_floor: float = 0.1,
        min_fit: float = 0.0,
        grow: str = "rated",
    ):
        if snap not in SNAPS:
            raise ValueError(f"snap must be one of {SNAPS}, got {snap!r}")
        if grow not in GROWTHS:
            raise ValueError(f"grow must be one of {GROWTHS}, got {grow!r}")
        if not 0.0 <= pose_floor <= 1.0:
            raise ValueError(f"pose_floor must lie in [0, 1], got {pose_floor}")
        if not 0.0 <= min_fit <= 1.0:
            raise ValueError(f"min_fit must lie in [0, 1], got {min_fit}")
        self.pose_floor = float(pose_floor)
        self.min_fit = float(min_fit)
        self.grow = grow
        self.net = net.eval()
        self.snap = snap
        self.threshold = float(threshold)
        self.seen_threshold = float(seen_threshold)
        self.record = dict(record or {})
        self.rule = CoverRule() if rule is None else rule
        # The exemplar stays the same through an episode: what is read of it (the matcher's
        # model, the network's embedding) is worked out once and kept until another shows.
        self._exemplar: Exemplar | None = None
        self._embedding: torch.Tensor | None = None

    def save(self, path: str | Path) -> None:
        """Write this locator (weights, thresholds, rule, record) to ``path``."""
        save_locator(
            self.net,
            path,
            self.threshold,
            self.seen_threshold,
            self.record,
            self.rule,
            self.snap,
            self.pose_floor,
            self.min_fit,
            self.grow,
        )

    @classmethod
    def load(cls, path: str | Path = SHIPPED_LOCATOR) -> TargetLocator:
        """The locator saved at ``path`` (the shipped one by default)."""
        if not Path(path).is_file():
            raise FileNotFoundError(f"no locator weights at {path}: train them with mpg-train-locator")
        header = read_locator_header(path)
        net = LocatorNet(LocatorConfig(**header["config"]))
        net.load_state_dict(load_file(str(path)))
        rule = CoverRule(**header["rule"]) if "rule" in header else CoverRule()
        snap, floor, min_fit = header.get("snap", "off"), header.get("pose_floor", 0.1), header.get("min_fit", 0.0)
        grow = header.get("grow", "rated")  # files written before the choice grew over every rated blob
        return cls(net, header["threshold"], header["seen_threshold"], header.get("record"), rule, snap, floor, min_fit, grow)

    def locate(self, obs: Mapping[str, np.ndarray]) -> Location:
        """Where the object of ``obs``' exemplar (``query_color``, ``query_depth``) shows in its
        heightmaps (``color``, ``depth``). Raises ``KeyError`` naming a missing entry."""
        missing = [k for k in ("color", "depth", "query_color", "query_depth") if k not in obs]
        if missing:
            raise KeyError(f"the locator needs an exemplar-mode observation; missing {missing}")
        exemplar, embedding = self._exemplar_embedding(obs)
        # Worked out once: the network's cues and the snap read the same colour gap and blobs.
        gap = None if exemplar.model is None else colour_gap(lab_colours(obs["color"]), exemplar.model[0])
        blobs = exemplar_blobs(obs, exemplar=exemplar, gap=gap)
        scene = torch.from_numpy(scene_input(obs, blobs=blobs, exemplar=exemplar, gap=gap))[None]
        with torch.no_grad():
            pixels, seen = self.net.scene_logits(scene, embedding)
        probability = torch.sigmoid(pixels[0]).numpy().astype(np.float32)
        seen_probability = float(torch.sigmoid(seen[0]))
        shown = seen_probability >= self.seen_threshold
        if not shown:
            return Location(probability, np.zeros(probability.shape, np.uint8), False, seen_probability)
        mask, ruled_out = None, None
        if self.snap == "template" and gap is not None:
            chosen = template_mask(probability, obs, exemplar, gap, blobs, self.min_fit, self.grow)
            if chosen is not None:
                return Location(probability, chosen[0].astype(np.uint8), True, seen_probability, chosen[1])
            # No blob of its colour shows (a camera's light can move every pixel off it): the
            # network's pixels above the threshold, as without snapping.
        elif self.snap != "off":
            weights, ruled_out = blob_weights(self.snap, blobs, exemplar, self.pose_floor)
            mask = snap_to_blob(probability, [b.pixels for b in blobs], self.threshold, weights)
        if mask is None:
            above = probability >= self.threshold
            mask = (above if ruled_out is None else above & ~ruled_out).astype(np.uint8)
            if ruled_out is not None and not mask.any():  # only objects that cannot be it rate high
                return Location(probability, mask, False, seen_probability)
        return Location(probability, mask, True, seen_probability)

    def _exemplar_embedding(self, obs: Mapping[str, np.ndarray]) -> tuple[Exemplar, torch.Tensor]:
        """``obs``' :class:`~mpg_agents.locator.features.Exemplar` and its network embedding,
        kept from the last call while the exemplar images are the same."""
        if self._exemplar is None or self._embedding is None or not self._exemplar.shows(obs):
            exemplar = Exemplar.of(obs)
            with torch.no_grad():
                query, descriptor = (torch.from_numpy(a)[None] for a in (exemplar.query, exemplar.descriptor))
                self._embedding = self.net.query_embedding(query, descriptor)
            self._exemplar = exemplar
        return self._exemplar, self._embedding
