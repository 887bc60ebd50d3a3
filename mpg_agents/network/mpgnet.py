"""MPGNet: the move/push/grasp fully convolutional Q-networks (paper Section III-B).

Each primitive's net (:mod:`mpg_agents.network.primitive_net`) encodes the colour and the depth
heightmap with two MobileNetV3 trunks; one mask trunk is shared by all nets. Features are
concatenated on channels and go through two 1x1 convolutions with batch norm and ReLU to one
Q channel, which is bilinearly upsampled back to the heightmap. Every heightmap is rotated to
the 16 orientations first and all 16 go through the trunks as one batch.

Rotation bookkeeping (conventions of :mod:`mpg_envs.grid.workspace`): for rotation ``k`` the input
is resampled so that the world direction ``theta_k`` (from +x = increasing column toward
+y = increasing row) becomes the +column direction of the rotated image; the net therefore
always "sees" its action along +column. The Q output of rotation ``k`` is resampled back
into the heightmap frame. Consequence used by the tests: rotating the scene by +90 degrees
maps the Q map of rotation ``k - 4`` to rotation ``k`` (rotated by the same 90 degrees).

Padding: before rotating, the 224 x 224 heightmaps are padded to ``ceil(224 * sqrt(2))``
rounded up to a multiple of 32 (= 320) so no corner is cut off. Every plane is padded with 0
after normalisation: the ImageNet mean colour, depth ``depth_mean`` (1 cm, near the table),
mask 0. Colour, depth and mask are stacked into one 5-channel tensor and rotated together.

Upsampling and un-rotation are one ``grid_sample`` from the coarse Q map: for every output
pixel we compute where it lies in the rotated, padded frame and interpolate the coarse map
bilinearly there. The coarse cell ``i`` of a stride-``s`` trunk is centred on input pixel
``s * i`` (each stride-2 convolution with ``(k - 1) / 2`` padding centres output ``j`` on
input ``2 j``), which the sampling grid accounts for.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from mpg_agents.network.finger_geometry import FingerGeometry
from mpg_agents.network.inputs import normalize_inputs
from mpg_agents.network.mobilenet import MobileNetV3Features, load_torchvision_features
from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_agents.network.primitive_net import PLANES, PrimitiveNet, run_in_batches, trunk_chunk
from mpg_agents.network.regions import footprint_top, grasp_pixels, least_blocked, region_max, target_region
from mpg_agents.network.rotations import rotation_grids
from mpg_envs.grid.primitive_specs import GRASP, MOVE, primitive_spec


@dataclass
class PreparedObs:
    """A batch normalised and stacked into input planes, before rotation (:meth:`MPGNet.prepare`)."""

    planes: Tensor  # (B, 5, H, W): colour, depth, mask as in PLANES
    region: Tensor  # (B, H, W) bool: the rough target mask (bounding rectangle)
    occluded: Tensor | None = field(default=None)  # (B,) bool when the observation had it
    grasp_region: Tensor | None = field(default=None)  # (B, H, W) bool; None: ``region``
    move_region: Tensor | None = field(default=None)  # (B, H, W) bool; None: ``region``
    grasp_fingers: Tensor | None = field(default=None)  # (B, R, H, W) bool: grasps whose fingers land clear enough
    move_fingers: Tensor | None = field(default=None)  # (B, R, H, W) bool: moves whose fingers land clear enough


@dataclass
class EncodedObs:
    """Normalised, padded and rotated inputs of a batch, plus the shared mask features.

    Produced by :meth:`MPGNet.encode`; lets the coordination run only the branches it needs
    without re-running the mask trunk.
    """

    planes: Tensor  # (N, 5, S, S), N = B * R rotated copies; channels as in PLANES
    mask_features: Tensor  # (N, C, h, w)
    rotations: Tensor  # (N,) rotation index of each copy
    batch_size: int
    region: Tensor  # (B, H, W) bool: the rough target mask (bounding rectangle)
    occluded: Tensor | None = field(default=None)  # (B,) bool when the observation had it
    grasp_region: Tensor | None = field(default=None)  # (B, H, W) bool; None: ``region``
    move_region: Tensor | None = field(default=None)  # (B, H, W) bool; None: ``region``
    grasp_fingers: Tensor | None = field(default=None)  # (B, R, H, W) bool; None: every grasp
    move_fingers: Tensor | None = field(default=None)  # (B, R, H, W) bool; None: every move

    def region_of(self, primitive: str) -> Tensor:
        """``(B, H, W)`` bool: where ``primitive`` may act (before ``rough_mask`` is consulted)."""
        if primitive == GRASP and self.grasp_region is not None:
            return self.grasp_region
        if primitive == MOVE and self.move_region is not None:
            return self.move_region
        return self.region


class MPGNet(nn.Module):
    """The three-branch Q-network; builds only ``config.primitives``.

    Inputs are raw observations (``color`` uint8 ``(B, 224, 224, 3)`` or channels-first,
    ``depth`` metres ``(B, 224, 224)``, ``mask`` 0/1 ``(B, 224, 224)``), as numpy arrays or
    tensors, batched or not. The output of :meth:`forward` is one ``(B, 16, 224, 224)`` Q
    tensor per primitive.

    Args:
        config: the architecture and its settings (default: the paper's).
        geometry: the env's grasp geometry; needed (and only read) when ``config`` asks for
            finger masks (``grasp_fingers`` or ``move_fingers`` ``"clear"``).

    Raises:
        ValueError: finger masks without a ``geometry``, or one of another heightmap size.
    """

    color_mean: Tensor  # buffers (register_buffer below)
    color_std: Tensor

    def __init__(self, config: MPGNetConfig | None = None, geometry: FingerGeometry | None = None) -> None:
        super().__init__()
        self.config = config if config is not None else MPGNetConfig()
        cfg = self.config
        if geometry is None and self.needs_geometry:
            raise ValueError(
                "this MPGNet masks grasps or moves by where the fingers land (grasp_fingers/move_fingers 'clear'), "
                "which needs the env's FingerGeometry (mpg_agents.acting.spaces.finger_geometry(env))"
            )
        if geometry is not None:
            geometry.check_size(cfg.heightmap_size)
        self.geometry = geometry
        self.mask_trunk = MobileNetV3Features(cfg.variant, 1, cfg.trunk_depth, cfg.bn_momentum)
        self.branches = nn.ModuleDict({p: PrimitiveNet(cfg, self.mask_trunk.out_channels) for p in cfg.primitives})
        self.output_stride = self.mask_trunk.output_stride
        if cfg.padded_size % self.output_stride:
            raise ValueError(
                f"padded size {cfg.padded_size} is not a multiple of the trunk's output stride {self.output_stride}"
            )
        self.register_buffer("color_mean", torch.tensor(cfg.color_mean).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("color_std", torch.tensor(cfg.color_std).view(1, 3, 1, 1), persistent=False)
        self._grid_cache: dict[tuple, Tensor] = {}
        if cfg.channels_last:
            self.to(memory_format=torch.channels_last)  # type: ignore[call-overload]  # torch's stubs omit it

    @property
    def primitives(self) -> tuple[str, ...]:
        """The branches this network has, in canonical order."""
        return self.config.primitives

    @property
    def needs_geometry(self) -> bool:
        """Whether the configuration asks for finger masks (made with a :class:`FingerGeometry`)."""
        return self.config.uses_finger_masks

    # ------------------------------------------------------------------ inputs
    def normalize(self, obs: Mapping[str, Any]) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor | None]:
        """:func:`mpg_agents.network.inputs.normalize_inputs` with this network's settings."""
        return normalize_inputs(obs, self.config, self.color_mean, self.color_std)

    # --------------------------------------------------------------- geometry
    def _grid(self, kind: str, coarse: int, device: torch.device, dtype: torch.dtype) -> Tensor:
        """Cached sampling grids: ``"in"`` rotates padded inputs, ``"out"`` un-rotates coarse maps."""
        key = (kind, coarse, device, dtype)
        if key not in self._grid_cache:
            self._grid_cache[key] = rotation_grids(
                self.config.num_rotations,
                self.config.heightmap_size,
                self.config.padded_size,
                kind,
                stride=self.output_stride,
            ).to(device=device, dtype=dtype)
        return self._grid_cache[key]

    def _padded(self, x: Tensor) -> Tensor:
        pad = (self.config.padded_size - self.config.heightmap_size) // 2
        return F.pad(x, (pad, pad, pad, pad))

    def _memory_format(self) -> torch.memory_format:
        return torch.channels_last if self.config.channels_last else torch.contiguous_format

    def _rotate(self, x: Tensor, rotations: Tensor) -> Tensor:
        """Pad ``x (B, C, H, W)`` and resample sample ``b`` at rotation ``rotations[b]``."""
        grid = self._grid("in", 0, x.device, x.dtype)[rotations]
        out = F.grid_sample(self._padded(x), grid, mode="bilinear", padding_mode="zeros", align_corners=True)
        return out.contiguous(memory_format=self._memory_format())

    def _rotate_all(self, x: Tensor) -> Tensor:
        """Pad ``x (B, C, H, W)`` and resample every sample at every rotation: ``(B * R, C, S, S)``.

        Rotation ``k + R/4`` is rotation ``k`` turned by exactly 90 degrees about the padded
        frame's centre, which maps pixel centres onto pixel centres; so only the first quarter
        is interpolated and the rest are exact ``rot90`` copies (4x less resampling, identical
        values). The whole batch is resampled in one call: the quarter's grids are stacked
        along the output rows, so each sample is read once and no loop runs per sample.
        """
        r, s = self.config.num_rotations, self.config.padded_size
        b, c = x.shape[:2]
        grids = self._grid("in", 0, x.device, x.dtype)
        quarter = r // 4 if r % 4 == 0 else r
        out = torch.empty((b * r, c, s, s), device=x.device, dtype=x.dtype, memory_format=self._memory_format())
        blocks = out.view(b, r // quarter, quarter, c, s, s)
        stacked = grids[:quarter].reshape(1, quarter * s, s, 2).expand(b, -1, -1, -1)
        base = F.grid_sample(self._padded(x), stacked, mode="bilinear", padding_mode="zeros", align_corners=True)
        base = base.view(b, c, quarter, s, s).transpose(1, 2)  # (B, quarter, C, S, S)
        for turns in range(r // quarter):
            blocks[:, turns].copy_(torch.rot90(base, turns, dims=(3, 4)) if turns else base)
        return out

    def _unrotate(self, coarse: Tensor, rotations: Tensor) -> Tensor:
        """Upsample + un-rotate + crop coarse maps ``(N, 1, h, w)`` to ``(N, H, W)`` in one resampling."""
        grid = self._grid("out", coarse.shape[-1], coarse.device, coarse.dtype)[rotations]
        return F.grid_sample(coarse, grid, mode="bilinear", padding_mode="border", align_corners=True)[:, 0]

    # ---------------------------------------------------------------- forward
    def prepare(self, obs: Mapping[str, Any]) -> PreparedObs:
        """Normalise a raw batch and stack it into input planes (done once per observation)."""
        color, depth, mask, binary, occluded = self.normalize(obs)
        cfg = self.config
        # Depth is normalised here: the bands are scaled by the same std (the clip at depth_max is far above).
        grasp_region = None
        if cfg.grasp_region in ("target", "visible"):
            band = cfg.visible_band_m / cfg.depth_std if cfg.grasp_region == "visible" else None
            grasp_region = grasp_pixels(binary, depth, cfg.target_margin_px, band)
        move_region = footprint_top(binary, depth, cfg.move_band_m / cfg.depth_std) if cfg.move_region == "top" else None
        region = target_region(binary)
        blocked = self._finger_blocking(depth) if self.needs_geometry else None
        grasp_fingers = move_fingers = None
        if cfg.grasp_fingers == "clear":
            assert blocked is not None  # a "clear" setting needs the geometry (checked at construction)
            grasp_fingers = least_blocked(blocked, region if grasp_region is None else grasp_region, cfg.finger_tolerance_m)
        if cfg.move_fingers == "clear":
            assert blocked is not None
            move_fingers = least_blocked(blocked, region if move_region is None else move_region, cfg.finger_tolerance_m)
        return PreparedObs(
            torch.cat([color, depth, mask], dim=1), region, occluded, grasp_region, move_region, grasp_fingers, move_fingers
        )

    def _finger_blocking(self, depth: Tensor) -> Tensor:
        """How far the open fingers of a grasp (or a move, which grasps the same way) at every
        pixel and rotation land blocked, ``(B, R, H, W)`` metres, from the normalised depth
        planes ``(B, 1, H, W)`` (the clip at ``depth_max`` lies far above any finger)."""
        cfg = self.config
        assert self.geometry is not None  # checked when built
        metres = (depth[:, 0].float() * cfg.depth_std + cfg.depth_mean).cpu().numpy()
        return torch.from_numpy(self.geometry.blocked(metres, cfg.num_rotations)).to(depth.device)

    def encode(self, obs: Mapping[str, Any] | PreparedObs, rotations: Tensor | None = None) -> EncodedObs:
        """Pad and rotate a batch and run the shared mask trunk once.

        Args:
            obs: raw observation dict (see class docstring), or a :class:`PreparedObs` to rotate
                one observation several times without normalising it again.
            rotations: ``None`` for all ``num_rotations`` per sample (sample-major order), one
                rotation index per sample ``(B,)`` (the training path: only the chosen rotation),
                or ``(B, K)``: each sample's ``K`` listed rotations (behaviour cloning's sampled ones).
        """
        prep = obs if isinstance(obs, PreparedObs) else self.prepare(obs)
        b = prep.planes.shape[0]
        r = self.config.num_rotations
        device = prep.planes.device
        if rotations is None:
            rot = torch.arange(r, device=device).repeat(b)
            planes = self._rotate_all(prep.planes)
        else:
            asked = torch.as_tensor(rotations, device=device).long()
            shaped = asked.dim() in (1, 2) and asked.shape[0] == b and asked.numel() > 0
            if not shaped or not 0 <= asked.min() <= asked.max() < r:
                raise ValueError(f"rotations must be ({b},) or ({b}, K) indices in 0..{r - 1}, got {asked.tolist()}")
            rot = asked.reshape(-1)  # sample-major: each sample's K copies side by side (one: no copy of the planes)
            planes = self._rotate(prep.planes.repeat_interleave(asked.shape[1], 0) if asked.dim() == 2 else prep.planes, rot)
        size = trunk_chunk(self.config, self.training, planes)
        return EncodedObs(
            planes=planes,
            mask_features=run_in_batches(self.mask_trunk, planes, size, first_channel=PLANES["mask"]),
            rotations=rot,
            batch_size=b,
            region=prep.region,
            occluded=prep.occluded,
            grasp_region=prep.grasp_region,
            move_region=prep.move_region,
            grasp_fingers=prep.grasp_fingers,
            move_fingers=prep.move_fingers,
        )

    def branch_q(self, enc: EncodedObs, primitive: str, subset: Tensor | None = None) -> Tensor:
        """Q maps of one primitive for the copies in ``enc`` (optionally only ``subset`` of them).

        Returns ``(N, H, W)`` in copy order; the rough mask is applied for move and grasp.
        """
        if primitive not in self.branches:
            raise ValueError(f"this MPGNet has no {primitive!r} branch; it has {self.primitives}")
        planes, feats, rot = enc.planes, enc.mask_features, enc.rotations
        if subset is not None:
            planes, feats, rot = planes[subset], feats[subset], rot[subset]
        q = self._unrotate(self.branches[primitive](planes, feats), rot)
        if self.config.rough_mask and primitive_spec(primitive).rough_masked:
            q = q * enc.region_of(primitive)[_sample_of(enc, subset)]
        return q

    def actable(self, enc: EncodedObs, primitive: str) -> Tensor | None:
        """``(B, R, H, W)`` or ``(B, 1, H, W)`` bool: where ``primitive`` may act (the rough mask's
        region for move and grasp, and their finger masks); ``None``: everywhere."""
        allowed = (
            enc.region_of(primitive)[:, None] if self.config.rough_mask and primitive_spec(primitive).rough_masked else None
        )
        fingers = {GRASP: enc.grasp_fingers, MOVE: enc.move_fingers}.get(primitive)
        if fingers is not None:
            allowed = fingers if allowed is None else allowed & fingers
        return allowed

    def grasp_where(self, enc: EncodedObs) -> Tensor:
        """``(B, R, H, W)`` or ``(B, 1, H, W)`` bool: the grasps the grasp score ranges over (the
        grasp region, and the finger mask when there is one)."""
        where = enc.region_of(GRASP)[:, None]
        return where if enc.grasp_fingers is None else where & enc.grasp_fingers

    def forward(self, obs: Mapping[str, Any], primitives: Sequence[str] | None = None) -> dict[str, Tensor]:
        """Q maps ``{primitive: (B, R, H, W)}`` for ``primitives`` (default: all branches)."""
        primitives = self.primitives if primitives is None else tuple(primitives)
        enc = self.encode(obs)
        return self.maps_from(enc, primitives)

    def maps_from(self, enc: EncodedObs, primitives: Sequence[str]) -> dict[str, Tensor]:
        """Q maps ``{primitive: (B, K, H, W)}`` from an :class:`EncodedObs` of ``K`` rotations per
        sample (``K = num_rotations`` when encoded with all of them)."""
        size = self.config.heightmap_size
        return {p: self.branch_q(enc, p).view(enc.batch_size, -1, size, size) for p in primitives}

    def chosen_q(
        self, obs: Mapping[str, Any], primitives: Sequence[str], action_primitive: Tensor, rotation: Tensor
    ) -> Tensor:
        """Q maps ``(B, H, W)`` of only the chosen primitive and rotation of each sample.

        This is the training path (as in VPG): each sample's heightmaps are rotated once and
        go through one branch, so the loss reaches exactly the chosen rotation and batch norm
        sees only chosen-rotation inputs.

        Args:
            obs: raw observation batch.
            primitives: the action space's primitive order ``action_primitive`` indexes into.
            action_primitive: ``(B,)`` index into ``primitives``.
            rotation: ``(B,)`` rotation index.
        """
        enc = self.encode(obs, rotations=rotation)
        prim = torch.as_tensor(action_primitive, device=enc.rotations.device).long().reshape(-1)
        if prim.numel() != enc.batch_size or (prim < 0).any() or (prim >= len(primitives)).any():
            raise ValueError(
                f"action_primitive must be {enc.batch_size} indices into {tuple(primitives)}, got {prim.tolist()}"
            )
        size = self.config.heightmap_size
        out = enc.planes.new_zeros((enc.batch_size, size, size))
        for i, name in enumerate(primitives):
            subset = torch.nonzero(prim == i).flatten()
            if subset.numel():
                out = out.index_put((subset,), self.branch_q(enc, name, subset))
        return out

    # ------------------------------------------------------------- utilities
    def grasp_score(self, obs: Mapping[str, Any]) -> Tensor:
        """Best grasp Q where a grasp may act, per sample ``(B,)`` (the discriminator's score)."""
        enc = self.encode(obs)
        q = self.maps_from(enc, (GRASP,))[GRASP]
        return region_max(q, self.grasp_where(enc))

    def load_imagenet(self, path: str | Path) -> None:
        """Initialise every trunk from a torchvision MobileNetV3 checkpoint of the same variant."""
        trunks = [self.mask_trunk] + [t for b in self.branches.values() for t in cast(PrimitiveNet, b).trunks]
        for trunk in trunks:
            load_torchvision_features(trunk, path)


def flat_q(maps: Mapping[str, Tensor], primitives: Sequence[str]) -> Tensor:
    """Flat Q ``(B, P * R * H * W)`` in an env's action order (C order over primitive,
    rotation, row, col, primitives as listed), from ``{primitive: (B, R or K, H, W)}`` maps."""
    missing = [p for p in primitives if p not in maps]
    if missing:
        raise KeyError(f"no Q maps for {missing}; have {sorted(maps)}")
    return torch.stack([maps[p] for p in primitives], dim=1).flatten(1)


def recompute_batch_norm_statistics(net: nn.Module, forward: Any, *args: Any) -> None:
    """Replace every BN layer's running statistics by those of one train-mode pass.

    ``forward(*args)`` is run once without gradients with cumulative-average statistics. A
    freshly initialised network in eval mode uses mean 0 / variance 1, under which MobileNet
    activations shrink layer by layer to ~1e-8 (flat Q maps, and denormal floats that make
    CPU inference several times slower); benchmarks and tests of an untrained network call
    this first. The network is left in eval mode.
    """
    norms = [m for m in net.modules() if isinstance(m, nn.BatchNorm2d)]
    momenta = [m.momentum for m in norms]
    for m in norms:
        m.reset_running_stats()
        m.momentum = None
    net.train()
    try:
        with torch.no_grad():
            forward(*args)
    finally:
        for m, momentum in zip(norms, momenta, strict=True):
            m.momentum = momentum
        net.eval()


def _sample_of(enc: EncodedObs, subset: Tensor | None) -> Tensor:
    """Sample index of each copy of ``enc`` (restricted to ``subset``)."""
    n = enc.rotations.shape[0]
    per = n // enc.batch_size
    idx = torch.arange(n, device=enc.rotations.device) // per
    return idx if subset is None else idx[subset]
