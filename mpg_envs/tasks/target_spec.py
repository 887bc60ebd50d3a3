"""How an episode names its target to the policy: the env keyword ``target_spec``.

- ``"mask"`` (the default, the paper's protocol): ``mask`` is the target's whole footprint,
  covered parts included, from the simulator; every registered id's episodes are as they were.
- ``"visible"``: ``mask`` holds only the footprint's pixels where the target is the top
  surface (empty while it is hidden), as a modal segmenter on a camera image gives.
- ``"exemplar"``: the observation has no ``mask`` and no ``occluded``: the policy is told
  nothing the simulator knows of where the target is. ``query_color`` and ``query_depth``
  show the target alone, resting in a random stable pose and yaw on an empty table, as
  colour and depth heightmaps at the observation's scale
  (:class:`~mpg_envs.tasks.exemplar_query.ExemplarQuery`); the scene's colours follow the
  look-alike rule (:mod:`mpg_envs.scenes.lookalikes`), so one object answers the query. Its
  scene is the one the same seed gives in the other modes (the same bodies and start poses):
  the colours and the query are drawn from the reset's seed in a stream of their own.

In every mode ``info`` keeps ``visible_fraction``, ``occluded`` and the rest. The env judges
every step on the simulator's view (the whole footprint and the cover flag:
:data:`SIMULATOR_KEYS`), whatever the policy is shown. In exemplar mode reset's ``info`` adds
``lookalikes`` (how many other objects share the target's colour, its shape) and a step's
``wrong_grasp_lookalike`` (a mis-pick lifted an object sharing the target's colour or shape)
and ``wrong_grasp_shares`` (what it shared: ``"colour"``, ``"shape"``).
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np
from gymnasium import spaces

from mpg_envs.grid.workspace import Workspace
from mpg_envs.perception.visual_randomization import VisualRandomization
from mpg_envs.scenes.lookalikes import PALETTE, exemplar_colours, shape_key, shared_looks
from mpg_envs.tasks.config import EnvConfig, observation_space
from mpg_envs.tasks.episode_sim import EpisodeSim
from mpg_envs.tasks.exemplar_query import ExemplarQuery
from mpg_envs.tasks.stages import StageSpec

TARGET_SPECS = ("mask", "visible", "exemplar")
"""The ways an env can name its target (the keyword ``target_spec``)."""

QUERY_KEYS = ("query_color", "query_depth")
"""The exemplar's entries of an exemplar-mode observation."""

SIMULATOR_KEYS = ("color", "depth", "mask", "occluded")
"""The observation the env judges steps on (and the ``"mask"`` mode shows)."""

_STREAM = 0x45584D50  # spawn key of the exemplar stream: independent of the scene's and the visuals' draws


def check_target_spec(value: Any, stage: StageSpec) -> str:
    """``value`` as a target spec for ``stage``'s env.

    Raises:
        ValueError: not one of :data:`TARGET_SPECS`, or ``"exemplar"`` for a stage without a
            target (Stage I: every object is one).
    """
    if not isinstance(value, str) or value not in TARGET_SPECS:
        raise ValueError(f"target_spec must be one of {TARGET_SPECS}, got {value!r}")
    if value == "exemplar" and stage.mask_all_objects:
        raise ValueError(f"target_spec='exemplar' needs a target; {stage.env_id} has none (every object is a target)")
    return value


def target_observation_space(spec: str, workspace: Workspace = Workspace()) -> spaces.Dict:
    """The observation space of an env naming its target by ``spec``: the common one
    (:func:`~mpg_envs.tasks.config.observation_space`) for ``mask`` and ``visible``; colour,
    depth and the query's colour and depth heightmaps for ``exemplar``."""
    common = observation_space(workspace)
    if spec != "exemplar":
        return common
    color, depth = common.spaces["color"], common.spaces["depth"]
    return spaces.Dict({"color": color, "depth": depth, "query_color": color, "query_depth": depth})


def exemplar_rng(seed: int, part: int) -> np.random.Generator:
    """The exemplar stream's generator ``part`` (0: the colours, 1: the query) of a reset ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(_STREAM, int(part))))


class TargetNaming:
    """One env's way of naming its target: what its observations show and what it adds to ``info``.

    Attributes:
        spec: one of :data:`TARGET_SPECS`.
        colours: exemplar mode: this episode's palette index of each object
            (:data:`~mpg_envs.scenes.lookalikes.PALETTE`; -1 for an object not in the scene), else ``None``.
        shapes: exemplar mode: each object's shape key (:func:`~mpg_envs.scenes.lookalikes.shape_key`), else ``None``.
        query: exemplar mode: this episode's ``{"query_color", "query_depth"}``, else ``None``.
    """

    def __init__(
        self,
        spec: str,
        stage: StageSpec,
        config: EnvConfig,
        obs_mode: str,
        camera_config: Any = None,
        randomization: VisualRandomization | None = None,
    ):
        self.spec = check_target_spec(spec, stage)
        self.colours: tuple[int, ...] | None = None
        self.shapes: tuple[Any, ...] | None = None
        self.query: dict[str, np.ndarray] | None = None
        self.target: int | None = None
        self._query = ExemplarQuery(config, obs_mode, camera_config, randomization) if self.spec == "exemplar" else None

    @property
    def top_mask(self) -> bool:
        """Whether observations need the pixels where the target shows (``visible`` mode)."""
        return self.spec == "visible"

    def start_episode(self, sim: EpisodeSim, target: int | None, seed: int | None, rng: np.random.Generator) -> None:
        """Exemplar mode: paint the scene of ``sim`` by the look-alike rule and take the query,
        from the reset's ``seed`` (``None``: a seed drawn from ``rng``, the env's generator), with
        ``sim.visuals``. Nothing in the other modes."""
        if self._query is None:
            return
        world = sim.world
        if world is None or target is None or not world.active[target]:
            raise ValueError("target_spec='exemplar' needs a scene with its target in it")
        seed = int(rng.integers(2**63)) if seed is None else int(seed)
        active = [int(i) for i in world.active_objects()]
        shapes = tuple(shape_key(asset) for asset in world.assets)
        drawn = exemplar_colours([shapes[i] for i in active], active.index(target), exemplar_rng(seed, 0))
        colours = [-1] * world.num_objects
        for i, colour in zip(active, drawn):
            colours[i] = colour
        sim.paint_objects([PALETTE[c] if c >= 0 else world.assets[i].rgba for i, c in enumerate(colours)])
        self.colours, self.shapes, self.target = tuple(colours), shapes, target
        color, depth = self._query.images(
            world.assets[target],
            PALETTE[colours[target]],
            exemplar_rng(seed, 1),
            sim.visuals,
            sim.ik,
        )
        self.query = {"query_color": color, "query_depth": depth}

    def public(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """What the policy is shown of the env's observation ``obs`` (the arrays, not copies)."""
        if self.spec == "mask":
            return obs
        if self.spec == "visible":
            return {
                "color": obs["color"],
                "depth": obs["depth"],
                "mask": obs["top_mask"],
                "occluded": obs["occluded"],
            }
        if self.query is None:
            raise RuntimeError("no exemplar yet: reset the env first")
        return {"color": obs["color"], "depth": obs["depth"], **self.query}

    def reset_info(self) -> dict[str, Any]:
        """Exemplar mode: ``lookalikes``, how many other objects in the scene share the target's
        colour and its shape; else nothing."""
        if self.colours is None or self.spec != "exemplar":
            return {}
        others = [i for i, c in enumerate(self.colours) if c >= 0 and i != self.target]
        # Drawn with the colours at reset.
        shapes, target = cast(tuple, self.shapes), cast(int, self.target)
        looks = [shared_looks(shapes, self.colours, target, i) for i in others]
        return {"lookalikes": {look: sum(look in shared for shared in looks) for look in ("colour", "shape")}}

    def step_info(self, wrong_grasp: bool, grasped_object: int | None) -> dict[str, Any]:
        """Exemplar mode: whether the step's mis-pick (``wrong_grasp``, lifting
        ``grasped_object``) took a look-alike and what it shared; else nothing."""
        if self.colours is None or self.spec != "exemplar":
            return {}
        shares = (
            shared_looks(cast(tuple, self.shapes), self.colours, cast(int, self.target), grasped_object)
            if wrong_grasp and grasped_object is not None
            else ()
        )
        return {"wrong_grasp_lookalike": bool(shares), "wrong_grasp_shares": shares}

    def close(self) -> None:
        """Free the query's worlds."""
        if self._query is not None:
            self._query.close()
