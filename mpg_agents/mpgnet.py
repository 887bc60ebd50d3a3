"""MPGNet: the move/push/grasp fully convolutional Q-networks (paper Section III-B).

Each primitive's net encodes the colour and the depth heightmap with two MobileNetV3 trunks;
one mask trunk is shared by all nets. Features are concatenated on channels and go through
two 1x1 convolutions with batch norm and ReLU to one Q channel, which is bilinearly
upsampled back to the heightmap. Every heightmap is rotated to the 16 orientations first
and all 16 go through the trunks as one batch.

Rotation bookkeeping (conventions of :mod:`mpg_envs.workspace`): for rotation ``k`` the input
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

import json
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import torch
from torch import Tensor, nn
from torch.nn import functional as F

from mpg_agents.mobilenet import DEFAULT_BN_MOMENTUM, MobileNetV3Features, full_depth, load_torchvision_features
from mpg_envs.actions import HEIGHTMAP_SIZE, PRIMITIVES, check_primitives
from mpg_envs.workspace import NUM_ROTATIONS

IMAGENET_MEAN: tuple[float, float, float] = (0.485, 0.456, 0.406)
IMAGENET_STD: tuple[float, float, float] = (0.229, 0.224, 0.225)

# Primitives whose Q maps the rough target mask restricts (paper, Training Details).
ROUGH_MASKED: tuple[str, ...] = ("move", "grasp")

# Trunk depth of the CPU-friendly variant: features.0-3 of MobileNetV3-small, output stride 8
# (24 channels). The whole trunk (stride 32) maps the 320-pixel padded input to 10 x 10 cells
# of 6.4 cm, coarser than the blocks themselves: trained from scratch on a CPU, its greedy
# grasps landed on the edges of the target's rectangle (14% target grasp success after 2000
# iterations, below random pixels inside the rectangle). Stride 8 gives 1.6 cm cells and a
# receptive field the size of a block, and a decision costs less. ``trunk_depth=None`` keeps
# the whole trunk.
SMALL_TRUNK_DEPTH: int | None = 4

# Settings of how the network runs, not of what it computes: a checkpoint's values of these
# are not imposed on the machine that loads it (see MPGNetConfig.from_checkpoint).
EXECUTION_FIELDS: tuple[str, ...] = ("channels_last", "trunk_batch")

CHECKPOINT_FORMAT = "mpgnet-safetensors-v1"

# The input planes, stacked on channels and rotated together; each trunk's stem reads its own
# channels from the stack (mobilenet.window_weight), so no plane is copied out of it (5 channels).
PLANES: dict[str, int] = {"color": 0, "depth": 3, "mask": 4}


@dataclass
class MPGNetConfig:
    """Architecture and input normalisation of MPGNet (paper defaults: ``variant="large"``).

    Attributes:
        variant: MobileNetV3 size of every trunk, ``"large"`` (paper) or ``"small"``.
        primitives: the branches to build, a subset of ``("move", "push", "grasp")`` in that order.
        trunk_depth: ``features`` modules kept in each trunk; ``None`` = the whole trunk
            (output stride 32). :meth:`small` uses :data:`SMALL_TRUNK_DEPTH`.
        head_channels: width of the hidden 1x1 convolution (VPG's 64).
        num_rotations: orientations per primitive (16, 22.5 degrees apart).
        heightmap_size: side of the square heightmaps (224).
        depth_max: depth is clipped to ``[0, depth_max]`` metres (the workspace height).
        depth_mean, depth_std: depth normalisation (VPG's heightmap statistics: most pixels
            are table at 0 m, objects a few cm high).
        color_mean, color_std: ImageNet statistics applied to colour / 255.
        rough_mask: zero move and grasp Q outside the target's bounding rectangle.
        bn_momentum: batch-norm momentum of the trunks (see ``mobilenet.DEFAULT_BN_MOMENTUM``).
        channels_last: keep weights and activations channels-last (NHWC); 2-3x faster
            depthwise convolutions on CPU. Not part of the architecture (checkpoints load
            either way).
        trunk_batch: most rotated images per trunk convolution at inference; ``None`` = all
            16 at once. The rotations still form one batch (resampled together, one set of BN
            statistics in training); this only splits the inference convolutions so their
            activations stay in the CPU caches: a 16-image batch at 320 x 320 has ~100 MB per
            expanded layer of MobileNetV3-large (26 MB for the small stem), past a 32 MB L3,
            and 4-image micro-batches were the fastest on 2 cores for both variants
            (``benchmarks/policy_speed.py``). Not part of the architecture.
    """

    variant: str = "large"
    primitives: tuple[str, ...] = PRIMITIVES
    trunk_depth: int | None = None
    head_channels: int = 64
    num_rotations: int = NUM_ROTATIONS
    heightmap_size: int = HEIGHTMAP_SIZE
    depth_max: float = 0.4
    depth_mean: float = 0.01
    depth_std: float = 0.03
    color_mean: tuple[float, float, float] = IMAGENET_MEAN
    color_std: tuple[float, float, float] = IMAGENET_STD
    rough_mask: bool = True
    bn_momentum: float = DEFAULT_BN_MOMENTUM
    channels_last: bool = True
    trunk_batch: int | None = 4

    def __post_init__(self) -> None:
        self.primitives = check_primitives(self.primitives)
        self.color_mean = tuple(float(v) for v in self.color_mean)  # type: ignore[assignment]
        self.color_std = tuple(float(v) for v in self.color_std)  # type: ignore[assignment]
        if self.variant not in ("large", "small"):
            raise ValueError(f"variant must be 'large' or 'small', got {self.variant!r}")
        if self.trunk_depth is not None and not 1 <= self.trunk_depth <= full_depth(self.variant):
            raise ValueError(
                f"trunk_depth for variant {self.variant!r} must be None or in 1..{full_depth(self.variant)}, "
                f"got {self.trunk_depth}"
            )
        if self.heightmap_size <= 0 or self.heightmap_size % 2:
            raise ValueError(f"heightmap_size must be a positive even number, got {self.heightmap_size}")
        if self.num_rotations < 1:
            raise ValueError(f"num_rotations must be positive, got {self.num_rotations}")
        if self.depth_std <= 0 or self.depth_max <= 0:
            raise ValueError("depth_std and depth_max must be positive")
        if self.trunk_batch is not None and self.trunk_batch < 1:
            raise ValueError(f"trunk_batch must be None or positive, got {self.trunk_batch}")

    @classmethod
    def small(cls, **overrides: Any) -> "MPGNetConfig":
        """The CPU-friendly variant: MobileNetV3-small trunks (depth :data:`SMALL_TRUNK_DEPTH`)."""
        overrides.setdefault("trunk_depth", SMALL_TRUNK_DEPTH)
        return cls(variant="small", **overrides)

    @classmethod
    def large(cls, **overrides: Any) -> "MPGNetConfig":
        """The paper's variant: full MobileNetV3-large trunks."""
        return cls(variant="large", **overrides)

    @classmethod
    def for_variant(cls, variant: str, **overrides: Any) -> "MPGNetConfig":
        """:meth:`small` or :meth:`large` by name."""
        if variant == "small":
            return cls.small(**overrides)
        if variant == "large":
            return cls.large(**overrides)
        raise ValueError(f"variant must be 'large' or 'small', got {variant!r}")

    @property
    def padded_size(self) -> int:
        """Side of the padded heightmap: ``ceil(size * sqrt 2)`` rounded up to a multiple of 32."""
        return int(math.ceil(math.ceil(self.heightmap_size * math.sqrt(2.0)) / 32.0) * 32)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable form (tuples become lists)."""
        data = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in data.items()}

    @classmethod
    def from_checkpoint(cls, data: Mapping[str, Any], **overrides: Any) -> "MPGNetConfig":
        """A checkpoint's architecture (its header's ``config``) with this variant's execution
        settings (:data:`EXECUTION_FIELDS`), then ``overrides``."""
        if "variant" not in data:
            raise ValueError("checkpoint config has no 'variant'")
        architecture = {k: v for k, v in data.items() if k not in EXECUTION_FIELDS}
        return cls.from_dict({**cls.for_variant(data["variant"]).to_dict(), **architecture, **overrides})

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "MPGNetConfig":
        """Inverse of :meth:`to_dict`; unknown keys raise ``ValueError``."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown MPGNetConfig keys {unknown}; valid keys: {sorted(known)}")
        kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**kwargs)


class QHead(nn.Sequential):
    """Two 1x1 convolutions with batch norm and ReLU (VPG's pre-activation order), 1 output channel.

    BN -> ReLU -> conv(C -> hidden) -> BN -> ReLU -> conv(hidden -> 1): the last layer is
    linear so Q can be negative (the move and push rewards go down to -0.5).
    """

    def __init__(self, in_channels: int, hidden: int) -> None:
        super().__init__(
            nn.BatchNorm2d(in_channels),
            nn.ReLU(inplace=True),
            nn.Conv2d(in_channels, hidden, 1, bias=False),
            nn.BatchNorm2d(hidden),
            nn.ReLU(inplace=True),
            nn.Conv2d(hidden, 1, 1),
        )
        for module in self.modules():
            if isinstance(module, nn.Conv2d):
                nn.init.kaiming_normal_(module.weight)


class PrimitiveNet(nn.Module):
    """One primitive's Q-network: colour trunk, depth trunk and head (the mask trunk is shared)."""

    def __init__(self, config: MPGNetConfig, mask_channels: int) -> None:
        super().__init__()
        self.trunk_batch = config.trunk_batch
        self.color_trunk = MobileNetV3Features(config.variant, 3, config.trunk_depth, config.bn_momentum)
        # Depth and mask are single-channel: a 1-channel stem is equivalent to replicating them to
        # 3 channels (an ImageNet stem is loaded by summing its RGB kernels) and 3x cheaper.
        self.depth_trunk = MobileNetV3Features(config.variant, 1, config.trunk_depth, config.bn_momentum)
        channels = self.color_trunk.out_channels + self.depth_trunk.out_channels + mask_channels
        self.head = QHead(channels, config.head_channels)

    def forward(self, planes: Tensor, mask_features: Tensor) -> Tensor:
        """Coarse Q map ``(N, 1, h, w)`` from rotated, padded input planes (:data:`PLANES`) and
        mask-trunk features."""
        size = None if self.training else self.trunk_batch
        color_f = run_in_batches(self.color_trunk, planes, size, first_channel=PLANES["color"])
        depth_f = run_in_batches(self.depth_trunk, planes, size, first_channel=PLANES["depth"])
        return self.head(torch.cat([color_f, depth_f, mask_features], dim=1))


@dataclass
class PreparedObs:
    """A batch normalised and stacked into input planes, before rotation (:meth:`MPGNet.prepare`)."""

    planes: Tensor  # (B, 5, H, W): colour, depth, mask as in PLANES
    region: Tensor  # (B, H, W) bool: the rough target mask (bounding rectangle)
    occluded: Tensor | None = field(default=None)  # (B,) bool when the observation had it


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


class MPGNet(nn.Module):
    """The three-branch Q-network; builds only ``config.primitives``.

    Inputs are raw observations (``color`` uint8 ``(B, 224, 224, 3)`` or channels-first,
    ``depth`` metres ``(B, 224, 224)``, ``mask`` 0/1 ``(B, 224, 224)``), as numpy arrays or
    tensors, batched or not. The output of :meth:`forward` is one ``(B, 16, 224, 224)`` Q
    tensor per primitive.
    """

    def __init__(self, config: MPGNetConfig | None = None) -> None:
        super().__init__()
        self.config = config if config is not None else MPGNetConfig()
        cfg = self.config
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
            self.to(memory_format=torch.channels_last)

    @property
    def primitives(self) -> tuple[str, ...]:
        """The branches this network has, in canonical order."""
        return self.config.primitives

    # ------------------------------------------------------------------ inputs
    def _batched(self, obs: Mapping[str, Any]) -> tuple[Tensor, Tensor, Tensor, Tensor | None]:
        """Validate and bring ``color``/``depth``/``mask`` to ``(B, C, H, W)`` tensors."""
        missing = [k for k in ("color", "depth", "mask") if k not in obs]
        if missing:
            raise KeyError(f"observation lacks {missing}; MPGNet needs 'color', 'depth' and 'mask'")
        device = self.color_mean.device
        size = self.config.heightmap_size
        color = torch.as_tensor(np.asarray(obs["color"]) if not isinstance(obs["color"], Tensor) else obs["color"])
        depth = torch.as_tensor(np.asarray(obs["depth"]) if not isinstance(obs["depth"], Tensor) else obs["depth"])
        mask = torch.as_tensor(np.asarray(obs["mask"]) if not isinstance(obs["mask"], Tensor) else obs["mask"])
        originals = {"color": tuple(color.shape), "depth": tuple(depth.shape), "mask": tuple(mask.shape)}
        expected = {
            "color": f"({size}, {size}, 3), (B, {size}, {size}, 3) or (B, 3, {size}, {size})",
            "depth": f"({size}, {size}), (B, {size}, {size}) or (B, 1, {size}, {size})",
            "mask": f"({size}, {size}), (B, {size}, {size}) or (B, 1, {size}, {size})",
        }

        def bad(key: str) -> ValueError:
            return ValueError(f"observation '{key}' has shape {originals[key]}; expected {expected[key]}")

        single = color.dim() == 3  # one unbatched observation: (H, W, 3) or (3, H, W)
        if single:
            color = color.unsqueeze(0)
        if color.dim() != 4:
            raise bad("color")
        if color.shape[-1] == 3 and color.shape[1] != 3:
            color = color.permute(0, 3, 1, 2)
        if tuple(color.shape[1:]) != (3, size, size):
            raise bad("color")
        planes = []
        for key, t in (("depth", depth), ("mask", mask)):
            if single and t.dim() == 2:
                t = t.unsqueeze(0)
            if t.dim() == 3:
                t = t.unsqueeze(1)
            if t.dim() != 4 or tuple(t.shape[1:]) != (1, size, size):
                raise bad(key)
            planes.append(t)
        depth, mask = planes
        if not color.shape[0] == depth.shape[0] == mask.shape[0]:
            raise ValueError(
                f"batch sizes differ: color {color.shape[0]}, depth {depth.shape[0]}, mask {mask.shape[0]}"
            )
        occluded = None
        if "occluded" in obs:
            occ = obs["occluded"]
            occ = torch.as_tensor(np.asarray(occ) if not isinstance(occ, Tensor) else occ)
            occluded = occ.reshape(color.shape[0], -1)[:, 0].to(device) > 0.5
        return color.to(device), depth.to(device), mask.to(device), occluded

    def normalize(self, obs: Mapping[str, Any]) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor | None]:
        """Normalised ``color (B,3,H,W)``, ``depth (B,1,H,W)``, ``mask (B,1,H,W)`` float tensors,
        the binary mask and the ``occluded`` flags (``None`` when absent).

        Colour: uint8 is divided by 255 (float input is taken to be on the same 0..255 scale,
        which is what SB3 hands over when ``normalize_images=False``), then ImageNet mean/std.
        Depth: clipped to ``[0, depth_max]`` m, then ``(d - depth_mean) / depth_std``.
        Mask: binarised at 0.5.
        """
        color, depth, mask, occluded = self._batched(obs)
        cfg = self.config
        color = (color.float() / 255.0 - self.color_mean) / self.color_std
        depth = depth.float()
        if not torch.isfinite(depth).all():
            raise ValueError("observation 'depth' contains NaN or infinite values; fill holes before acting")
        depth = (depth.clamp(0.0, cfg.depth_max) - cfg.depth_mean) / cfg.depth_std
        binary = mask > 0.5 if mask.dtype != torch.bool else mask
        return color, depth, binary.float(), binary[:, 0], occluded

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
        values).
        """
        r, s = self.config.num_rotations, self.config.padded_size
        b, c = x.shape[:2]
        grids = self._grid("in", 0, x.device, x.dtype)
        quarter = r // 4 if r % 4 == 0 else r
        out = torch.empty((b * r, c, s, s), device=x.device, dtype=x.dtype, memory_format=self._memory_format())
        blocks = out.view(b, r // quarter, quarter, c, s, s)
        padded = self._padded(x)
        for i in range(b):
            source = padded[i : i + 1].expand(quarter, -1, -1, -1)
            base = F.grid_sample(source, grids[:quarter], mode="bilinear", padding_mode="zeros", align_corners=True)
            for turns in range(r // quarter):
                blocks[i, turns].copy_(torch.rot90(base, turns, dims=(2, 3)) if turns else base)
        return out

    def _unrotate(self, coarse: Tensor, rotations: Tensor) -> Tensor:
        """Upsample + un-rotate + crop coarse maps ``(N, 1, h, w)`` to ``(N, H, W)`` in one resampling."""
        grid = self._grid("out", coarse.shape[-1], coarse.device, coarse.dtype)[rotations]
        return F.grid_sample(coarse, grid, mode="bilinear", padding_mode="border", align_corners=True)[:, 0]

    @staticmethod
    def target_region(mask: Tensor) -> Tensor:
        """Rough target mask ``(B, H, W)`` bool: the mask's axis-aligned bounding rectangle.

        An empty mask (target not visible) gives an all-true region: there is nothing to
        localise, so Q is left unrestricted rather than zeroed everywhere.
        """
        if mask.dim() == 4:
            mask = mask[:, 0]
        mask = mask > 0.5 if mask.dtype != torch.bool else mask
        rows, cols = mask.any(dim=2), mask.any(dim=1)
        h, w = mask.shape[1:]
        ar_h = torch.arange(h, device=mask.device)
        ar_w = torch.arange(w, device=mask.device)

        def span(any_: Tensor, ar: Tensor, n: int) -> Tensor:
            first = torch.where(any_, ar, n).amin(dim=1, keepdim=True)
            last = torch.where(any_, ar, -1).amax(dim=1, keepdim=True)
            inside = (ar >= first) & (ar <= last)
            empty = ~any_.any(dim=1, keepdim=True)
            return inside | empty

        return span(rows, ar_h, h)[:, :, None] & span(cols, ar_w, w)[:, None, :]

    # ---------------------------------------------------------------- forward
    def prepare(self, obs: Mapping[str, Any]) -> PreparedObs:
        """Normalise a raw batch and stack it into input planes (done once per observation)."""
        color, depth, mask, binary, occluded = self.normalize(obs)
        return PreparedObs(torch.cat([color, depth, mask], dim=1), self.target_region(binary), occluded)

    def encode(self, obs: Mapping[str, Any] | PreparedObs, rotations: Tensor | None = None) -> EncodedObs:
        """Pad and rotate a batch and run the shared mask trunk once.

        Args:
            obs: raw observation dict (see class docstring), or a :class:`PreparedObs` to rotate
                one observation several times without normalising it again.
            rotations: ``None`` for all ``num_rotations`` per sample (sample-major order), or one
                rotation index per sample ``(B,)`` (the training path: only the chosen rotation).
        """
        prep = obs if isinstance(obs, PreparedObs) else self.prepare(obs)
        b = prep.planes.shape[0]
        r = self.config.num_rotations
        device = prep.planes.device
        if rotations is None:
            rot = torch.arange(r, device=device).repeat(b)
            planes = self._rotate_all(prep.planes)
        else:
            rot = torch.as_tensor(rotations, device=device).long().reshape(-1)
            if rot.numel() != b or (rot < 0).any() or (rot >= r).any():
                raise ValueError(f"rotations must be {b} indices in 0..{r - 1}, got {rotations}")
            planes = self._rotate(prep.planes, rot)
        size = None if self.training else self.config.trunk_batch
        return EncodedObs(
            planes=planes,
            mask_features=run_in_batches(self.mask_trunk, planes, size, first_channel=PLANES["mask"]),
            rotations=rot,
            batch_size=b,
            region=prep.region,
            occluded=prep.occluded,
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
        if self.config.rough_mask and primitive in ROUGH_MASKED:
            q = q * enc.region[_sample_of(enc, subset)]
        return q

    def forward(self, obs: Mapping[str, Any], primitives: Sequence[str] | None = None) -> dict[str, Tensor]:
        """Q maps ``{primitive: (B, R, H, W)}`` for ``primitives`` (default: all branches)."""
        primitives = self.primitives if primitives is None else tuple(primitives)
        enc = self.encode(obs)
        return self.maps_from(enc, primitives)

    def maps_from(self, enc: EncodedObs, primitives: Sequence[str]) -> dict[str, Tensor]:
        """Q maps ``{primitive: (B, R, H, W)}`` from an all-rotation :class:`EncodedObs`."""
        r, size = self.config.num_rotations, self.config.heightmap_size
        return {p: self.branch_q(enc, p).view(enc.batch_size, r, size, size) for p in primitives}

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
        """Best grasp Q inside the target region, per sample ``(B,)`` (the discriminator score)."""
        enc = self.encode(obs)
        q = self.maps_from(enc, ("grasp",))["grasp"]
        return region_max(q, enc.region)

    def load_imagenet(self, path: str | Path) -> None:
        """Initialise every trunk from a torchvision MobileNetV3 checkpoint of the same variant."""
        trunks = [self.mask_trunk] + [t for b in self.branches.values() for t in (b.color_trunk, b.depth_trunk)]
        for trunk in trunks:
            load_torchvision_features(trunk, path)


def flat_q(maps: Mapping[str, Tensor], primitives: Sequence[str]) -> Tensor:
    """Flat Q ``(B, P * R * H * W)`` in an env's action order (C order over primitive,
    rotation, row, col, primitives as listed), from ``{primitive: (B, R, H, W)}`` maps."""
    missing = [p for p in primitives if p not in maps]
    if missing:
        raise KeyError(f"no Q maps for {missing}; have {sorted(maps)}")
    return torch.stack([maps[p] for p in primitives], dim=1).flatten(1)


def run_in_batches(module: nn.Module, x: Tensor, size: int | None, **kwargs: Any) -> Tensor:
    """``module(x, **kwargs)`` computed ``size`` samples at a time (all at once for ``None``)."""
    if size is None or x.shape[0] <= size:
        return module(x, **kwargs)
    return torch.cat([module(part, **kwargs) for part in x.split(size)], dim=0)


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


def region_max(q: Tensor, region: Tensor) -> Tensor:
    """Max of ``q (B, R, H, W)`` over rotations and the pixels where ``region (B, H, W)`` is true."""
    masked = q.masked_fill(~region[:, None], float("-inf"))
    return masked.flatten(1).amax(dim=1)


def rotation_grids(num_rotations: int, size: int, padded: int, kind: str, stride: int = 1) -> Tensor:
    """Sampling grids for ``F.grid_sample(..., align_corners=True)``.

    ``kind="in"``: ``(R, S, S, 2)``; rotated image pixel ``p`` samples the padded input at
    ``c + R(theta_k) (p - c)`` so world direction ``theta_k`` becomes +column.
    ``kind="out"``: ``(R, H, W, 2)``; heightmap pixel ``q`` (padded frame ``q + pad``) samples
    the coarse map of rotation ``k`` at ``(c + R(-theta_k)(q + pad - c)) / stride`` in cell units.
    Angles are computed in float64 so multiples of 90 degrees land exactly on pixel centres.
    """
    pad = (padded - size) // 2
    centre = (padded - 1) / 2.0
    k = np.arange(num_rotations)
    theta = k * 2.0 * np.pi / num_rotations
    cos, sin = np.cos(theta), np.sin(theta)
    # Snap the exact cases (cos/sin of multiples of 90 degrees) to remove 6e-17 residues.
    cos = np.where(np.abs(cos) < 1e-12, 0.0, cos)
    sin = np.where(np.abs(sin) < 1e-12, 0.0, sin)
    if kind == "in":
        coords = np.arange(padded, dtype=np.float64) - centre
        n_src, sign = padded, 1.0
    elif kind == "out":
        coords = np.arange(size, dtype=np.float64) + pad - centre
        n_src, sign = padded // stride, -1.0
    else:
        raise ValueError(f"kind must be 'in' or 'out', got {kind!r}")
    gy, gx = np.meshgrid(coords, coords, indexing="ij")  # rows = y, cols = x
    c, s = cos[:, None, None], sign * sin[:, None, None]
    src_x = c * gx - s * gy + centre
    src_y = s * gx + c * gy + centre
    if kind == "out":
        src_x, src_y = src_x / stride, src_y / stride
    # align_corners=True: index 0 -> -1, index n-1 -> +1.
    norm = lambda v: 2.0 * v / (n_src - 1) - 1.0  # noqa: E731
    grid = np.stack([norm(src_x), norm(src_y)], axis=-1)
    return torch.from_numpy(grid.astype(np.float32))


# ----------------------------------------------------------------- checkpoint
def checkpoint_metadata(
    net: MPGNet, q_star: float = float("nan"), extra: Mapping[str, Any] | None = None
) -> dict[str, str]:
    """The safetensors metadata header: one JSON document under key ``"mpgnet"``."""
    header = {
        "format": CHECKPOINT_FORMAT,
        "variant": net.config.variant,
        "primitives": list(net.primitives),
        "q_star": None if math.isnan(q_star) else float(q_star),
        "config": net.config.to_dict(),
    }
    if extra:
        header["extra"] = dict(extra)
    return {"mpgnet": json.dumps(header)}


def save_mpgnet(
    net: MPGNet, path: str | Path, q_star: float = float("nan"), extra: Mapping[str, Any] | None = None
) -> None:
    """Write ``net``'s weights (and BN statistics) to a safetensors file with a JSON header."""
    from safetensors.torch import save_file

    state = {k: v.detach().cpu().contiguous() for k, v in net.state_dict().items()}
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    save_file(state, str(path), metadata=checkpoint_metadata(net, q_star, extra))


def read_checkpoint_header(path: str | Path) -> dict[str, Any]:
    """The JSON header of an MPGNet safetensors file (no tensors are read)."""
    from safetensors import safe_open

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"MPGNet checkpoint not found: {path}")
    try:
        with safe_open(str(path), framework="pt") as f:
            meta = f.metadata() or {}
    except Exception as exc:  # noqa: BLE001 - re-raised naming the file
        raise ValueError(
            f"{path} is not a safetensors file ({exc}); MPGNet weights are saved with save_weights()"
        ) from exc
    if "mpgnet" not in meta:
        raise ValueError(f"{path} has no 'mpgnet' metadata header; it was not written by save_mpgnet/save_weights")
    header = json.loads(meta["mpgnet"])
    if header.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(
            f"{path}: unsupported checkpoint format {header.get('format')!r}, expected {CHECKPOINT_FORMAT!r}"
        )
    return header


def load_mpgnet_weights(net: MPGNet, path: str | Path, strict_branches: bool = True) -> dict[str, Any]:
    """Load a :func:`save_mpgnet` file into ``net`` after checking the architectures match.

    Branches in the file that ``net`` does not have are ignored. With ``strict_branches=False``
    branches of ``net`` missing from the file keep their current weights (e.g. a Stage II
    grasp-only checkpoint starting Stage V); otherwise that is an error.

    Returns:
        The checkpoint header (variant, primitives, q_star, config).

    Raises:
        ValueError: naming the mismatch (variant, trunk depth, head width, a tensor's shape, a
            missing branch) when the file holds another architecture.
    """
    from safetensors.torch import load_file

    header = read_checkpoint_header(path)
    file_cfg = header.get("config", {})
    mine = net.config.to_dict()
    for key in ("variant", "trunk_depth", "head_channels", "num_rotations", "heightmap_size"):
        if file_cfg.get(key) != mine[key]:
            raise ValueError(
                f"checkpoint {path} has {key}={file_cfg.get(key)!r} but this network has {key}={mine[key]!r}; "
                "build the network with the checkpoint's configuration (MPGNetConfig.from_dict(header['config']))"
            )
    missing_branches = [p for p in net.primitives if p not in header.get("primitives", [])]
    if missing_branches and strict_branches:
        raise ValueError(
            f"checkpoint {path} has branches {header.get('primitives')} but this network needs {list(net.primitives)} "
            f"(missing {missing_branches}); pass strict_branches=False to keep those branches' current weights"
        )
    state = load_file(str(path))
    own = net.state_dict()
    wanted = {}
    for key, target in own.items():
        if key.startswith("branches.") and key.split(".")[1] in missing_branches:
            continue
        if key not in state:
            raise ValueError(f"checkpoint {path} lacks tensor {key!r} that this {net.config.variant} MPGNet needs")
        if tuple(state[key].shape) != tuple(target.shape):
            raise ValueError(
                f"checkpoint {path}: tensor {key!r} has shape {tuple(state[key].shape)}, this network needs "
                f"{tuple(target.shape)}"
            )
        wanted[key] = state[key]
    net.load_state_dict(wanted, strict=False)
    return header


def load_mpgnet(path: str | Path, primitives: Sequence[str] | None = None) -> tuple[MPGNet, dict[str, Any]]:
    """Build an MPGNet from a checkpoint's own configuration and load it.

    Args:
        path: a :func:`save_mpgnet` safetensors file.
        primitives: branches to keep (default: all the file has).
    """
    header = read_checkpoint_header(path)
    cfg = MPGNetConfig.from_checkpoint(header["config"])
    if primitives is not None:
        cfg.primitives = check_primitives(primitives)
    net = MPGNet(cfg)
    load_mpgnet_weights(net, path)
    return net, header
