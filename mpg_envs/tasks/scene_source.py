"""Where a reset's scene comes from: a shipped test set, or objects dropped afresh.

:func:`draw_scene` drops objects with the stage's generator (:mod:`mpg_envs.scenes.generators`) until a
scene meets the episode's start condition: every object resting inside the workspace, and a
candidate target that is occluded or surrounded as the stage asks and whose visible fraction
lies in the asked band. A band that asks for a mostly hidden target (upper bound at most
:data:`BURY_BELOW`) switches the stage's generator to its buried variant, which drops
occluders onto the target by construction, so such scenes are not found by slow rejection.
A reset never returns a scene outside its band: :class:`~mpg_envs.scenes.generators.InvalidSceneError`
when none is made in ``EnvConfig.scene_tries`` draws.

:func:`shipped_scene` looks a seed up in the stage's shipped test set
(:mod:`mpg_envs.scenes.test_sets`), used only with the settings the set was generated with.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

from mpg_envs.perception.occlusion import in_band, surrounded_sectors
from mpg_envs.scenes.scene_io import SceneFile
from mpg_envs.scenes.generators import BURIED, SCENES, InvalidSceneError, SceneConfig, keep_inside

if TYPE_CHECKING:  # the env imports this module
    from mpg_envs.tasks.env import MPGEnv

BURY_BELOW = 0.5
"""A visible-fraction band whose upper bound is at most this uses the buried generator."""


def generator_name(scene: str, band: tuple[float, float] | None) -> str:
    """The generator that makes the stage's ``scene`` for a visible-fraction ``band``."""
    if band is not None and band[1] <= BURY_BELOW and scene in BURIED:
        return BURIED[scene]
    return scene


def draw_scene(env: MPGEnv) -> None:
    """Drop a scene for ``env`` (sets ``env.world`` and ``env.target``); see the module
    docstring. Raises :class:`InvalidSceneError` naming why no draw was valid."""
    rng = env.np_random
    stage = env.stage
    name = generator_name(stage.scene, env.visible_range)
    scene_fn = SCENES[name]
    astray_draws = 0
    for _ in range(env.config.scene_tries):
        picks = rng.integers(len(env.object_set), size=env.num_objects)
        world = env._build_world([env.object_set[int(k)] for k in picks])
        layout = scene_fn(world, rng, env.config.scene)
        redropped = keep_inside(world, rng, layout, env.config.scene)
        if redropped is None:
            astray_draws += 1
            continue
        if not layout.targets:
            env.target = None
            return
        # Re-dropped objects landed on the pile afterwards: no longer "the n-th dropped".
        target = acceptable_target(env, [t for t in layout.targets if t not in redropped])
        if target is not None:
            env.target = target
            return
    raise InvalidSceneError(
        f"{stage.env_id}: no valid scene of {env.num_objects} objects in {env.config.scene_tries} draws "
        f"({astray_draws} with objects left outside the workspace or not at rest after "
        f"{env.config.scene.redrop_rounds} re-drop rounds, the others with no candidate target meeting the "
        f"start condition: occluded={stage.start_occluded}, surrounded sectors>={stage.start_surrounded}, "
        f"visible fraction in {env.visible_range}). Raise EnvConfig.scene_tries, widen visible_range or use "
        f"fewer objects."
    )


def acceptable_target(env: MPGEnv, candidates: Sequence[int]) -> int | None:
    """The first candidate meeting the stage's start condition (occlusion, surround) and the
    env's visible-fraction band, or ``None``."""
    stage = env.stage
    band = env.visible_range
    if stage.start_occluded is None and not stage.start_surrounded and band is None:
        return candidates[0] if candidates else None
    maps = env._heightmaps()
    for target in candidates:
        mask, occluded = env._target_view(maps.depth, target)
        if stage.start_occluded is not None and occluded != stage.start_occluded:
            continue
        if band is not None and not in_band(env._visible_fraction(maps, mask, target), band):
            continue
        if surrounded_sectors(maps.depth, mask) >= stage.start_surrounded:
            return target
    return None


def shipped_scene(env: MPGEnv, seed: int | None) -> SceneFile | None:
    """The shipped test-set scene of ``seed`` for ``env``, or ``None`` when the env has no
    test set for its object count, the seed is not in it, or the env's settings differ from
    those the set was generated with (its scenes would not be the env's)."""
    if seed is None or not env.use_test_set or env.stage.test_set is None:
        return None
    if env.config.scene != SceneConfig() or env.config.object_set_seed != 0:
        return None
    if env.visible_range != env.stage.visible_range:
        return None
    from mpg_envs.scenes.test_sets import TEST_SET_WORKSPACE, find_test_set, test_set_name

    name = test_set_name(env.stage.test_set, env._object_set_name)  # the object set's own sets
    if env.config.workspace != TEST_SET_WORKSPACE or name is None:
        return None
    test_set = find_test_set(name, env.num_objects)
    if test_set is None or not test_set.has_seed(seed):
        return None
    return test_set.scene(seed, env.object_set)
