"""Where a reset's scene comes from: a shipped test set, objects dropped afresh, or (with the
env's ``arranged`` option) an arrangement drawn afresh (:func:`arranged_start`).

:func:`drop_scene` drops objects with the stage's generator (:mod:`mpg_envs.scenes.generators`) until a
scene meets the episode's start condition: every object resting inside the workspace, and a
candidate target that is occluded or surrounded as the stage asks and whose visible fraction
lies in the asked band. A band that asks for a mostly hidden target (upper bound at most
:data:`BURY_BELOW`) switches the stage's generator to its buried variant, which drops
occluders onto the target by construction, so such scenes are not found by slow rejection.
A reset never returns a scene outside its band: :class:`~mpg_envs.scenes.generators.InvalidSceneError`
when none is made in ``EnvConfig.scene_tries`` draws.

:func:`scene_from_test_set` looks a seed up in the stage's shipped test set
(:mod:`mpg_envs.scenes.test_sets`), used only with the settings the set was generated with, and
only if the set was made by this code: :func:`generator_digest` (the code that drops scenes and
its parameters) must be the one the set records, else
:class:`~mpg_envs.scenes.test_sets.StaleTestSetError` says how to regenerate it. Once loaded,
:func:`check_test_scene` compares the target's visible fraction with the recorded one
(:class:`~mpg_envs.scenes.test_sets.ChangedTestSetError` for a scene changed in its file).

Both work on the episode's simulation (:class:`~mpg_envs.tasks.episode_sim.EpisodeSim`) and a
:class:`SceneRequest` (what the reset asks for), never on the env itself.
:func:`checked_reset_options` checks the options a reset is given (:data:`RESET_OPTIONS`), each
of its type; :func:`start_scene` picks the source of a reset's scene (its ``scene`` option, the
test set, an arrangement, drops) and builds it.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import inspect
import json
import os
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any, cast

import numpy as np

from mpg_envs.perception.heightmap import RaycastHeightmapper
from mpg_envs.perception.occlusion import in_band, surrounded_sectors
from mpg_envs.scenes import generators
from mpg_envs.scenes.arranged import ArrangedScenes, ArrangementError, arrangement_scene, check_settled
from mpg_envs.scenes.arrangement_draw import draw_arrangement
from mpg_envs.scenes.generators import BURIED, GENERATORS, InvalidSceneError, keep_inside
from mpg_envs.scenes.scene_file import SceneFile, SceneFileError
from mpg_envs.scenes.scene_io import read_scene
from mpg_envs.scenes.scene_loading import load_scene
from mpg_envs.scenes.test_sets import TEST_SEEDS, TEST_SET_WORKSPACE, TestSet, find_test_set, test_set_name
from mpg_envs.simulation.assets import ObjectAsset
from mpg_envs.tasks.config import EnvConfig
from mpg_envs.tasks.episode_sim import EpisodeSim
from mpg_envs.tasks.stages import StageSpec

RESET_OPTIONS = ("scene", "mesh_dir", "drop_outside", "num_objects")
"""The options ``MPGEnv.reset(options=...)`` takes."""

BURY_BELOW = 0.5
"""A visible-fraction band whose upper bound is at most this uses the buried generator."""


@dataclass(frozen=True)
class SceneRequest:
    """What a reset asks of its scene (the env's settings for this episode).

    Attributes:
        stage: the env's stage (generator, start condition, test set).
        num_objects: objects in the scene.
        object_set: the assets objects are drawn from.
        object_set_name: the set's name (``"custom"`` for a list of assets).
        visible_range: the band of the target's visible fraction at reset, or ``None``.
        config: the env's settings.
        use_test_set: whether a test seed loads its shipped scene.
    """

    stage: StageSpec
    num_objects: int
    object_set: Sequence[ObjectAsset]
    object_set_name: str
    visible_range: tuple[float, float] | None
    config: EnvConfig
    use_test_set: bool = True


def generator_name(generator: str, band: tuple[float, float] | None) -> str:
    """The generator that makes the stage's ``generator``'s scenes for a visible-fraction ``band``."""
    if band is not None and band[1] <= BURY_BELOW and generator in BURIED:
        return BURIED[generator]
    return generator


def drop_scene(sim: EpisodeSim, request: SceneRequest) -> int | None:
    """Drop a scene into ``sim`` (drawing from ``sim.random``) and return its target (``None``
    when the mask shows every object); see the module docstring. Raises
    :class:`InvalidSceneError` naming why no draw was valid."""
    rng, stage, config = sim.random, request.stage, request.config
    name = generator_name(stage.generator, request.visible_range)
    scene_fn = GENERATORS[name]
    astray_draws = 0
    for _ in range(config.scene_tries):
        picks = rng.integers(len(request.object_set), size=request.num_objects)  # type: ignore[union-attr]  # drawn at reset
        world = sim.build([request.object_set[int(k)] for k in picks])
        layout = scene_fn(world, rng, config.generator)  # type: ignore[arg-type]
        redropped = keep_inside(world, rng, layout, config.generator)  # type: ignore[arg-type]
        if redropped is None:
            astray_draws += 1
            continue
        if not layout.targets:
            return None
        # Re-dropped objects landed on the pile afterwards: no longer "the n-th dropped".
        target = acceptable_target(sim, stage, request.visible_range, [t for t in layout.targets if t not in redropped])
        if target is not None:
            return target
    raise InvalidSceneError(
        f"{stage.env_id}: no valid scene of {request.num_objects} objects in {config.scene_tries} draws "
        f"({astray_draws} with objects left outside the workspace or not at rest after "
        f"{config.generator.redrop_rounds} re-drop rounds, the others with no candidate target meeting the "
        f"start condition: occluded={stage.start_occluded}, surrounded sectors>={stage.start_surrounded}, "
        f"visible fraction in {request.visible_range}). Raise EnvConfig.scene_tries, widen visible_range or use "
        f"fewer objects."
    )


def acceptable_target(
    sim: EpisodeSim, stage: StageSpec, band: tuple[float, float] | None, candidates: Sequence[int]
) -> int | None:
    """The first candidate meeting the stage's start condition (occlusion, surround) and the
    visible-fraction ``band`` in ``sim``'s current world, or ``None``."""
    if stage.start_occluded is None and not stage.start_surrounded and band is None:
        return candidates[0] if candidates else None
    maps = sim.heightmaps()
    for target in candidates:
        mask, occluded = sim.target_view(maps.depth, target)
        if stage.start_occluded is not None and occluded != stage.start_occluded:
            continue
        if band is not None and not in_band(sim.visible_fraction(maps, mask, target), band):
            continue
        if surrounded_sectors(maps.depth, mask) >= stage.start_surrounded:
            return target
    return None


def scene_from_test_set(request: SceneRequest, seed: int | None) -> SceneFile | None:
    """The shipped test-set scene of ``seed`` for ``request``, or ``None`` when the stage has
    no test set for its object count, the seed is not in it, or the request's settings differ
    from those the set was generated with (its scenes would not be the env's)."""
    test_set = _test_set_of(request, seed)
    if test_set is None:
        return None
    test_set.check_made_by(generator_digest(request))
    assert seed is not None  # _test_set_of finds no set without one
    return test_set.scene(seed, request.object_set)


def check_test_scene(sim: EpisodeSim, request: SceneRequest, seed: int, target: int | None, observed: float | None) -> None:
    """Raise :class:`~mpg_envs.scenes.test_sets.ChangedTestSetError` (naming the set, the seed
    and both values) unless the target's visible fraction in ``sim``'s world, just built from
    :func:`scene_from_test_set`'s scene of ``seed``, is the one its set records: a scene changed
    in its file since the set was made (a target moved 1 cm) is refused at its reset.

    Measured on a clean ray cast, as the set was: ``observed``, the fraction the reset's own
    observation measured, when that is one (ray-cast mode without visual randomization), so
    the check costs nothing; else a one-off clean ray cast of the world (:func:`clean_visible_fraction`)."""
    test_set = _test_set_of(request, seed)
    if test_set is None:
        raise ValueError(f"seed {seed} has no shipped test scene for {request.stage.env_id} at {request.num_objects} objects")
    clean = sim.obs_mode == "raycast" and sim.visuals is None
    test_set.check_visible_fraction(seed, observed if clean else clean_visible_fraction(sim, target))


def clean_visible_fraction(sim: EpisodeSim, target: int | None) -> float | None:
    """``target``'s visible fraction in a top-down ray cast of ``sim``'s world, without visual
    randomization (what a test set records); ``None`` without a target."""
    world = sim.world
    if world is None:
        raise RuntimeError("no world yet: build the scene first")
    with RaycastHeightmapper(world.model, sim.config.workspace, num_threads=1) as caster:
        maps = caster(world.data)
    mask, _ = sim.target_view(maps.depth, target)
    return sim.visible_fraction(maps, mask, target)


def _test_set_of(request: SceneRequest, seed: int | None) -> TestSet | None:
    """The shipped test set holding ``seed``'s scene for ``request`` (see
    :func:`scene_from_test_set`), or ``None``. Only a test seed reads a set's file."""
    stage, config = request.stage, request.config
    if seed is None or not request.use_test_set or stage.test_set is None:
        return None
    if config.object_set_seed != 0 or request.visible_range != stage.visible_range:
        return None
    name = test_set_name(stage.test_set, request.object_set_name)  # the object set's own sets
    if config.workspace != TEST_SET_WORKSPACE or name is None or int(seed) not in TEST_SEEDS:
        return None
    test_set = find_test_set(name, request.num_objects)
    if test_set is None or not test_set.has_seed(seed) or config.generator != test_set.generator_config:
        return None
    return test_set


def generator_digest(request: SceneRequest) -> str:
    """SHA-256 of what makes ``request``'s dropped scenes: the code (the generators module and
    this module's drop loop, docstrings and comments left out) and the parameters (generator,
    object count, start condition, generator, physics and workspace settings, draws, object
    set). A test set records it; a set whose digest differs was made by other code."""
    stage, config = request.stage, request.config
    params = {
        "generator": generator_name(stage.generator, request.visible_range),
        "num_objects": request.num_objects,
        "start_occluded": stage.start_occluded,
        "start_surrounded": stage.start_surrounded,
        "visible_range": request.visible_range,
        "bury_below": BURY_BELOW,
        "generator_config": asdict(config.generator),
        "physics": asdict(config.physics),
        "workspace": asdict(config.workspace),
        "scene_tries": config.scene_tries,
        "object_set": [request.object_set_name, config.object_set_seed],
    }
    text = _code_digest() + json.dumps(params, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@functools.cache
def _code_digest() -> str:
    parts = [inspect.getsource(generators)] + [inspect.getsource(f) for f in (drop_scene, acceptable_target, generator_name)]
    return hashlib.sha256("\n".join(code_fingerprint(part) for part in parts).encode()).hexdigest()


def code_fingerprint(source: str) -> str:
    """``source``'s syntax tree without docstrings, written back as source (comments and
    formatting are not in it): what runs. Written back rather than dumped, because
    ``ast.dump`` changes between Python versions (3.12 added fields) while the written-back
    source does not, so a test set made under one Python is this code's under another."""
    tree = ast.parse(source)
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if not isinstance(body, list) or not body:
            continue
        first = body[0]
        if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
            cast(Any, node).body = body[1:] or [ast.Pass()]  # a node with a body (mypy sees an ast.AST)
    return ast.unparse(tree)


def arranged_start(
    sim: EpisodeSim, request: SceneRequest, arranged: ArrangedScenes, load: Callable[[SceneFile], int | None]
) -> int | None:
    """Start the episode in ``sim`` from an arrangement drawn from ``sim.random`` (a kind of
    ``arranged.kinds``, then its seed), built by ``load`` (which builds a scene file's world and
    returns its target), and return its target; ``None`` when none of ``arranged.tries``
    draws stood as designed (:func:`~mpg_envs.scenes.arranged.check_settled`): the reset then
    drops a scene. See :class:`~mpg_envs.scenes.arranged.ArrangedScenes`."""
    rng = sim.random
    assert rng is not None  # drawn at reset
    for _ in range(arranged.tries):
        kind = arranged.kinds[int(rng.integers(len(arranged.kinds)))]
        arrangement = draw_arrangement(int(rng.integers(2**31)), request.config.workspace, kind=kind)
        scene = arrangement_scene(arrangement, request.config.workspace)
        target = load(scene)
        maps = sim.heightmaps()
        mask, _ = sim.target_view(maps.depth, target)
        try:
            world, visible = sim.world, sim.visible_fraction(maps, mask, target)
            assert world is not None and visible is not None  # built by load; an arrangement has a target
            check_settled(world, scene, arrangement, visible)
        except ArrangementError:
            continue
        return target
    return None


def checked_reset_options(options: Any) -> dict[str, Any]:
    """A copy of ``reset``'s ``options``, each of its type, else a ``ValueError`` naming the option
    and what is valid (``num_objects`` is checked against the stage by the env)."""
    if options is not None and not isinstance(options, dict):
        raise ValueError(f"reset options are {options!r}; valid: a dict with keys {sorted(RESET_OPTIONS)}, or None")
    options = dict(options or {})
    unknown = sorted(set(options) - set(RESET_OPTIONS), key=str)
    if unknown:
        raise ValueError(f"unknown reset options {unknown}; valid: {sorted(RESET_OPTIONS)}")
    for key, types, valid in (
        ("scene", (str, os.PathLike, SceneFile), "a scene file's path (str or Path) or a SceneFile"),
        ("mesh_dir", (str, os.PathLike), "a folder's path (str or Path)"),
        ("drop_outside", (bool, np.bool_), "True or False"),
    ):
        if options.get(key) is not None and not isinstance(options[key], types):
            raise ValueError(f"reset option {key!r} is {options[key]!r}; valid: {valid}, or None")
    return options


def start_scene(
    sim: EpisodeSim, request: SceneRequest, seed: int | None, options: dict[str, Any], arranged: ArrangedScenes | None
) -> tuple[int | None, int | None]:
    """Build a reset's scene in ``sim`` (its generator drawn: ``sim.initialize_episode``) and return
    ``(target, test_seed)``: the scene file of the ``scene`` option (``options``: checked by
    :func:`checked_reset_options`), else the shipped test set's scene of ``seed`` (``test_seed`` is
    then ``seed``: check it with :func:`check_test_scene` once observed; else ``None``), else, with
    ``arranged`` and at its share, a drawn arrangement (:func:`arranged_start`), else drops
    (:func:`drop_scene`)."""
    scene = options.get("scene")
    if scene is not None:
        if not isinstance(scene, SceneFile):
            scene = read_scene(scene, options.get("mesh_dir"), request.config.object_set_seed)
        return load_scene_file(sim, request, scene, drop_outside=bool(options.get("drop_outside", False))), None
    fixed = scene_from_test_set(request, seed)
    if fixed is not None:
        return load_scene_file(sim, request, fixed, drop_outside=False), seed
    # The share is drawn only with the option on: without it, episodes are as they were.
    # (sim.random: the episode's generator, drawn by initialize_episode)
    if arranged is not None and cast(np.random.Generator, sim.random).random() < arranged.share:
        target = arranged_start(sim, request, arranged, lambda s: load_scene(sim.build, s, request.config.workspace, False)[1])
        if target is not None:
            return target, None
    return drop_scene(sim, request), None


def load_scene_file(sim: EpisodeSim, request: SceneRequest, scene: SceneFile, drop_outside: bool) -> int | None:
    """Build the world of a scene file in ``sim`` (:func:`mpg_envs.scenes.scene_loading.load_scene`)
    and return its target; :class:`~mpg_envs.scenes.scene_io.SceneFileError` for a file without
    one when the stage needs one."""
    _, target = load_scene(sim.build, scene, request.config.workspace, drop_outside)
    if target is None and not request.stage.mask_all_objects:
        raise SceneFileError(f"scene {scene.source!r} has no target; {request.stage.env_id} needs one")
    return target
