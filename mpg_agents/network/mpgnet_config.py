"""MPGNet's configuration: architecture, input normalisation and how it runs (paper defaults)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from numbers import Integral
from typing import Any

from mpg_agents.network.mobilenet import DEFAULT_BN_MOMENTUM, full_depth
from mpg_agents.network.rotations import padded_side
from mpg_envs.grid.actions import HEIGHTMAP_SIZE, PRIMITIVES, check_primitives
from mpg_envs.grid.primitive_specs import primitive_spec
from mpg_envs.grid.workspace import NUM_ROTATIONS

IMAGENET_MEAN: tuple[float, float, float] = (0.485, 0.456, 0.406)
IMAGENET_STD: tuple[float, float, float] = (0.229, 0.224, 0.225)

# The paper's primitives whose Q maps the rough target mask restricts (paper, Training Details:
# move and grasp; each record's ``rough_masked``).
ROUGH_MASKED: tuple[str, ...] = tuple(p for p in PRIMITIVES if primitive_spec(p).rough_masked)

# Where a grasp may act: the paper's bounding rectangle, the target's footprint (grown or
# shrunk), or the part of it where the target itself shows (its lowest surface).
GRASP_REGIONS: tuple[str, ...] = ("rectangle", "target", "visible")
MOVE_REGIONS: tuple[str, ...] = ("rectangle", "top")
HEAD_INITS: tuple[str, ...] = ("kaiming", "zero")
# Which grasps may act: any (the paper), or only those whose open fingers land least blocked.
GRASP_FINGERS: tuple[str, ...] = ("any", "clear")

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


@dataclass
class MPGNetConfig:
    """Architecture and input normalisation of MPGNet (paper defaults: ``variant="large"``).

    Attributes:
        variant: MobileNetV3 size of every trunk, ``"large"`` (paper) or ``"small"``.
        primitives: the branches to build, a subset of ``("move", "push", "grasp")`` in that order.
        trunk_depth: ``features`` modules kept in each trunk; ``None`` = the whole trunk
            (output stride 32). :meth:`small` uses :data:`SMALL_TRUNK_DEPTH`.
        head_channels: width of the hidden 1x1 convolution (VPG's 64).
        head_dilation: 0 (the paper): the head's first convolution is 1x1; ``d`` > 0: it is
            3x3 with dilation ``d``, so a Q value also reads the trunk cells ``d`` away. The
            small trunk's features see about +-9 pixels (90% of an output's input gradient),
            the open gripper's finger pads come down +-23 pixels (9.3 cm apart) from the grasp
            point: without wider context a grasp net cannot tell which angle keeps the fingers
            clear of the neighbours. 3 on the stride-8 trunk reaches +-24 pixels further.
        head_init: the head's last convolution starts as ``"kaiming"`` (VPG's He-normal, the
            default) or ``"zero"`` (every Q 0 until trained). He-normal gives the untrained
            small net, in training mode, grasp Q values of standard deviation 0.5 with a maximum
            of 10 over one scene's 16 x 224 x 224 outputs, beyond every return the rewards
            allow; the TD targets and the greedy Q*_g calibration start from that random
            landscape. Zero removes it; the gradient reaches the earlier layers from the
            second step on.
        num_rotations: orientations per primitive (16, 22.5 degrees apart).
        heightmap_size: side of the square heightmaps (224).
        depth_max: depth is clipped to ``[0, depth_max]`` metres (the workspace height).
        depth_mean, depth_std: depth normalisation (VPG's heightmap statistics: most pixels
            are table at 0 m, objects a few cm high).
        color_mean, color_std: ImageNet statistics applied to colour / 255.
        rough_mask: zero move and grasp Q outside the target's bounding rectangle.
        grasp_region: where grasp Q may be non-zero when ``rough_mask`` is on: ``"rectangle"``
            (the paper's rough mask), ``"target"`` (the target's footprint grown by
            ``target_margin_px``; a grasp elsewhere in the rectangle lifts another object) or
            ``"visible"`` (as ``"target"``, on only the footprint's pixels within
            ``visible_band_m`` of its lowest surface, the target's own visible top,
            :func:`mpg_agents.network.regions.footprint_bottom`: a grasp there closes on the
            target, not on an object lying on it, so it may be taken while the target is
            still partly covered).
        target_margin_px: growth (> 0) or shrinking (< 0) of the target pixels for
            ``grasp_region="target"`` or ``"visible"``, in 2 mm pixels (see
            :func:`mpg_agents.network.regions.target_pixels`).
        visible_band_m: height band of ``grasp_region="visible"``, metres.
        move_region: where move Q may be non-zero when ``rough_mask`` is on: ``"rectangle"``
            (the paper's rough mask) or ``"top"`` (the target footprint's pixels within
            ``move_band_m`` of its highest point: the occluder's top; see
            :func:`mpg_agents.network.regions.footprint_top`).
        move_band_m: height band of ``move_region="top"``, metres.
        grasp_fingers: which grasps may act: ``"any"`` (the paper) or ``"clear"``: only those
            (pixel, angle) pairs whose open fingers come down least blocked, read off the depth
            heightmap with the 2F-85's geometry (:func:`mpg_envs.grid.grasp_geometry.fingers_blocked`,
            the env's default grasp depth and workspace): the free ones when a grasp in the grasp
            region has free landing strips, else the least blocked in that region, each up to
            ``finger_tolerance_m`` more blocked (:func:`mpg_agents.network.regions.least_blocked`). Two
            thirds of a trained net's greedy grasps in 15-object clutter lifted nothing, most
            with a neighbour under a finger; the small trunk does not see 4 cm to each side.
            It restricts greedy grasps, the grasp score compared with Q*_g and the TD target's
            greedy next action; exploratory grasps stay unrestricted.
        move_fingers: which moves may act, as ``grasp_fingers`` for grasps: ``"any"`` (the paper)
            or ``"clear"``: only the (pixel, angle) pairs in the move region whose open fingers
            come down least blocked. A move grasps the occluder to carry it aside; most of a
            trained net's moves in hard clutter closed at an angle where a finger landed on
            the occluder or a neighbour and lifted nothing.
        finger_tolerance_m: the slack of ``grasp_fingers="clear"`` and ``move_fingers="clear"``, metres.
        bn_momentum: batch-norm momentum of the trunks (see ``mobilenet.DEFAULT_BN_MOMENTUM``).
        color_input: the nets read the colour heightmap (the paper). ``False``: each primitive's
            net reads only depth and the shared mask features (no colour trunk: 4 trunk passes
            per rotation instead of 7), so a camera's colour (its light, its colours, its image
            placed off the target mask by a calibration error) cannot mislead it.
        channels_last: keep weights and activations channels-last (NHWC); 2-3x faster
            depthwise convolutions on CPU. Not part of the architecture (checkpoints load
            either way).
        trunk_batch: most rotated images per trunk convolution at inference on the CPU (an
            accelerator takes them all at once: :func:`~mpg_agents.network.primitive_net.trunk_chunk`); ``None`` = all
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
    head_dilation: int = 0
    head_init: str = "kaiming"
    num_rotations: int = NUM_ROTATIONS
    heightmap_size: int = HEIGHTMAP_SIZE
    depth_max: float = 0.4
    depth_mean: float = 0.01
    depth_std: float = 0.03
    color_mean: tuple[float, float, float] = IMAGENET_MEAN
    color_std: tuple[float, float, float] = IMAGENET_STD
    rough_mask: bool = True
    grasp_region: str = "rectangle"
    target_margin_px: int = 2
    move_region: str = "rectangle"
    move_band_m: float = 0.015
    visible_band_m: float = 0.01
    grasp_fingers: str = "any"
    move_fingers: str = "any"
    finger_tolerance_m: float = 0.005
    bn_momentum: float = DEFAULT_BN_MOMENTUM
    color_input: bool = True
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
        if self.head_dilation < 0:
            raise ValueError(f"head_dilation must be >= 0 (0: 1x1 head convolutions), got {self.head_dilation}")
        if self.head_init not in HEAD_INITS:
            raise ValueError(f"head_init must be one of {HEAD_INITS}, got {self.head_init!r}")
        if self.heightmap_size <= 0 or self.heightmap_size % 2:
            raise ValueError(f"heightmap_size must be a positive even number, got {self.heightmap_size}")
        if self.num_rotations < 1:
            raise ValueError(f"num_rotations must be positive, got {self.num_rotations}")
        if self.depth_std <= 0 or self.depth_max <= 0:
            raise ValueError("depth_std and depth_max must be positive")
        if self.grasp_region not in GRASP_REGIONS:
            raise ValueError(f"grasp_region must be one of {GRASP_REGIONS}, got {self.grasp_region!r}")
        if self.move_region not in MOVE_REGIONS:
            raise ValueError(f"move_region must be one of {MOVE_REGIONS}, got {self.move_region!r}")
        low, high = self.target_margin_range
        if (
            isinstance(self.target_margin_px, bool)
            or not isinstance(self.target_margin_px, Integral)
            or not low <= self.target_margin_px <= high
        ):
            raise ValueError(
                f"target_margin_px must be an integer in [{low}, {high}] "
                f"pixels, got {self.target_margin_px!r} (shrinking "
                f"by more than half the heightmap keeps each part's deepest pixels, as {low} does; growing by {high} "
                f"already covers the whole heightmap)"
            )
        if not self.visible_band_m >= 0:
            raise ValueError(f"visible_band_m must be >= 0 metres, got {self.visible_band_m}")
        if not self.move_band_m >= 0:
            raise ValueError(f"move_band_m must be >= 0 metres, got {self.move_band_m}")
        if self.grasp_fingers not in GRASP_FINGERS:
            raise ValueError(f"grasp_fingers must be one of {GRASP_FINGERS}, got {self.grasp_fingers!r}")
        if self.move_fingers not in GRASP_FINGERS:
            raise ValueError(f"move_fingers must be one of {GRASP_FINGERS}, got {self.move_fingers!r}")
        if not self.finger_tolerance_m >= 0:
            raise ValueError(f"finger_tolerance_m must be >= 0 metres, got {self.finger_tolerance_m}")
        if not isinstance(self.color_input, bool):
            raise ValueError(f"color_input must be True or False, got {self.color_input!r}")
        if self.trunk_batch is not None and self.trunk_batch < 1:
            raise ValueError(f"trunk_batch must be None or positive, got {self.trunk_batch}")

    @property
    def target_margin_range(self) -> tuple[int, int]:
        """The ``target_margin_px`` values that mean something, ``[low, high]``: shrinking past
        half the heightmap leaves each part of a mask its deepest pixels, as shrinking by half
        does (:func:`mpg_agents.network.regions.target_pixels`), and growing by the heightmap's
        side less one covers all of it from any pixel."""
        return -(self.heightmap_size // 2), self.heightmap_size - 1

    @classmethod
    def small(cls, **overrides: Any) -> MPGNetConfig:
        """The CPU-friendly variant: MobileNetV3-small trunks (depth :data:`SMALL_TRUNK_DEPTH`)."""
        overrides.setdefault("trunk_depth", SMALL_TRUNK_DEPTH)
        return cls(variant="small", **overrides)

    @classmethod
    def large(cls, **overrides: Any) -> MPGNetConfig:
        """The paper's variant: full MobileNetV3-large trunks."""
        return cls(variant="large", **overrides)

    @classmethod
    def for_variant(cls, variant: str, **overrides: Any) -> MPGNetConfig:
        """:meth:`small` or :meth:`large` by name."""
        if variant == "small":
            return cls.small(**overrides)
        if variant == "large":
            return cls.large(**overrides)
        raise ValueError(f"variant must be 'large' or 'small', got {variant!r}")

    @property
    def uses_finger_masks(self) -> bool:
        """Whether grasps or moves are masked by where the fingers land (``"clear"``), which
        needs the env's grasp geometry (:class:`~mpg_agents.network.finger_geometry.FingerGeometry`)."""
        return "clear" in (self.grasp_fingers, self.move_fingers)

    @property
    def padded_size(self) -> int:
        """Side of the padded heightmap: ``ceil(size * sqrt 2)`` rounded up to a multiple of 32."""
        return padded_side(self.heightmap_size)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable form (tuples become lists)."""
        data = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in data.items()}

    @classmethod
    def from_checkpoint(cls, data: Mapping[str, Any], **overrides: Any) -> MPGNetConfig:
        """A checkpoint's architecture (its header's ``config``) with this variant's execution
        settings (:data:`EXECUTION_FIELDS`), then ``overrides``."""
        if "variant" not in data:
            raise ValueError("checkpoint config has no 'variant'")
        architecture = {k: v for k, v in data.items() if k not in EXECUTION_FIELDS}
        return cls.from_dict({**cls.for_variant(data["variant"]).to_dict(), **architecture, **overrides})

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> MPGNetConfig:
        """Inverse of :meth:`to_dict`; unknown keys raise ``ValueError``."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown MPGNetConfig keys {unknown}; valid keys: {sorted(known)}")
        kwargs: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**kwargs)
