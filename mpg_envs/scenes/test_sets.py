"""Fixed, versioned test sets: the start states of the test envs' held-out seeds, shipped.

A test scene used to be re-simulated from its seed at every reset: seconds per reset, and a
start state that depends on the CPU and MuJoCo build that drops it. The test envs
(``MPG-Occluded-v0``, ``MPG-OccludedHard-v0``) instead load the scenes of their held-out
seeds from compact files shipped in the wheel (``mpg_envs/test_scenes/<name>_<objects>.npz``):
per scene, each object's asset (by name, from the ``blocks`` set), position and orientation
(float64, exactly as generated, at rest) and the target. ``reset(seed=i)`` on a seed of the
set rebuilds scene ``i`` in tens of milliseconds and gives the same observation on every
machine; any other seed is generated afresh as before, so users can still draw new scenes.

Each file records how it was made: the generator version (:data:`GENERATOR_VERSION`, bumped
when scene generation changes), a digest of the generator's code and parameters
(``generator_digest``: :func:`mpg_envs.tasks.scene_source.generator_digest`), the package and
MuJoCo versions, the env id, and each scene's visible fraction at reset.
``benchmarks/make_test_sets.py`` writes them. A set is used only by the generator that made it:
:meth:`TestSet.check_made_by` raises :class:`StaleTestSetError`, saying how to regenerate the
set, when the code that drops scenes has changed since.
"""

from __future__ import annotations

import functools
import json
from dataclasses import asdict, dataclass
from importlib import resources
from pathlib import Path
from typing import Sequence

import numpy as np

from mpg_envs.scenes.generators import GeneratorConfig
from mpg_envs.simulation.assets import ObjectAsset
from mpg_envs.scenes.scene_io import SceneFile, SceneObject
from mpg_envs.grid.workspace import Workspace

GENERATOR_VERSION = 1
"""Version of scene generation the shipped sets were made with."""

TEST_SEED_START = 500000
"""The held-out test seeds start here (Table I's evaluations use 500000 onwards)."""

TEST_SET_WORKSPACE = Workspace()
"""Test sets are made, and apply, on the default workspace only."""

FORMAT = "mpg-test-set"

OBJECT_SET_SUFFIXES: dict[str, str] = {"blocks": "", "random_urdfs_test": "_novel"}
"""Object sets that have shipped test sets, and the suffix of their sets' names
(``occluded_hard`` on blocks, ``occluded_hard_novel`` on the ``random_urdfs`` test split)."""


def test_set_name(stage_test_set: str, object_set: str) -> str | None:
    """The name of the shipped sets of a stage's test seeds (its ``StageSpec.test_set``) on
    ``object_set``, or ``None`` when that object set has none."""
    suffix = OBJECT_SET_SUFFIXES.get(object_set)
    return None if suffix is None else f"{stage_test_set}{suffix}"


test_set_name.__test__ = False  # type: ignore[attr-defined]  # not a pytest test


class StaleTestSetError(RuntimeError):
    """A test set was made by another scene generator (code, parameters or version) than the
    running code's: its scenes are not the ones this code drops for its seeds."""


@dataclass(frozen=True)
class TestSet:
    """The scenes of one test env at one object count.

    Attributes:
        name: the set's name (a :class:`~mpg_envs.tasks.stages.StageSpec`'s ``test_set``).
        num_objects: objects per scene.
        seeds: ``(S,)`` reset seeds, one per scene.
        assets: ``(S, N)`` asset names.
        positions: ``(S, N, 3)`` float64 world positions of the bodies.
        quats: ``(S, N, 4)`` float64 orientations (w first).
        targets: ``(S,)`` index of the target object in each scene.
        visible_fraction: ``(S,)`` the target's visible fraction at reset.
        meta: how the set was made (generator, package and MuJoCo versions, env id).
    """

    __test__ = False  # not a pytest test class

    name: str
    num_objects: int
    seeds: np.ndarray
    assets: np.ndarray
    positions: np.ndarray
    quats: np.ndarray
    targets: np.ndarray
    visible_fraction: np.ndarray
    meta: dict[str, str]

    def __post_init__(self) -> None:
        s, n = len(self.seeds), self.num_objects
        shapes = {"assets": (s, n), "positions": (s, n, 3), "quats": (s, n, 4), "targets": (s,), "visible_fraction": (s,)}
        for field, shape in shapes.items():
            if np.shape(getattr(self, field)) != shape:
                raise ValueError(f"test set {self.name!r}: {field} has shape {np.shape(getattr(self, field))}, expected {shape}")
        object.__setattr__(self, "_index", {int(seed): k for k, seed in enumerate(self.seeds)})

    def __len__(self) -> int:
        return len(self.seeds)

    def has_seed(self, seed: int) -> bool:
        """Whether ``seed`` is one of the set's scenes."""
        return int(seed) in self._index  # type: ignore[attr-defined]

    def scene(self, seed: int, object_set: Sequence[ObjectAsset]) -> SceneFile:
        """The scene of ``seed`` with its assets taken from ``object_set`` (by name)."""
        if not self.has_seed(seed):
            raise KeyError(f"seed {seed} is not in test set {self.name!r} ({len(self)} scenes, seeds {self.seeds[0]}..{self.seeds[-1]})")
        k = self._index[int(seed)]  # type: ignore[attr-defined]
        by_name = {asset.name: asset for asset in object_set}
        objects = []
        for i, name in enumerate(self.assets[k]):
            if name not in by_name:
                raise KeyError(f"test set {self.name!r}: asset {name!r} is not in the object set ({sorted(by_name)})")
            objects.append(SceneObject(by_name[name], self.positions[k, i], self.quats[k, i], True, f"object {i} ({name!r})"))
        return SceneFile(tuple(objects), int(self.targets[k]), f"{self.name}_{self.num_objects}:{seed}", simulated=True)

    @property
    def generator_config(self) -> GeneratorConfig:
        """The generator settings the set's scenes were dropped with (recorded by
        :func:`generator_meta`; a set that records none was made with the defaults)."""
        recorded = self.meta.get("generator_config")
        return GeneratorConfig() if recorded is None else GeneratorConfig(**json.loads(recorded))

    def check_made_by(self, digest: str) -> None:
        """Raise :class:`StaleTestSetError` unless the set was made by generator version
        :data:`GENERATOR_VERSION` with code and parameters of ``digest``."""
        made = self.meta.get("generator_digest"), self.meta.get("generator_version")
        if made == (digest, str(GENERATOR_VERSION)):
            return
        env_id = self.meta.get("env_id", "<its env id>")
        raise StaleTestSetError(
            f"test set {self.name}_{self.num_objects} was made by another scene generator (digest {made[0]!r}, "
            f"version {made[1]!r}) than this code's (digest {digest!r}, version {GENERATOR_VERSION}): its scenes are "
            f"not what this code drops for its seeds. Regenerate it with `python benchmarks/make_test_sets.py "
            f"--envs {env_id} --objects {self.num_objects}` (or reset with use_test_set=False to drop every scene)."
        )

    def save(self, path: str | Path) -> Path:
        """Write the set as a compressed ``.npz``."""
        path = Path(path)
        meta = {"format": FORMAT, "name": self.name, **self.meta}
        np.savez_compressed(
            path,
            seeds=self.seeds.astype(np.int64),
            assets=self.assets.astype(str),
            positions=self.positions.astype(np.float64),
            quats=self.quats.astype(np.float64),
            targets=self.targets.astype(np.int16),
            visible_fraction=self.visible_fraction.astype(np.float32),
            meta_keys=np.array(list(meta), dtype=str),
            meta_values=np.array([str(v) for v in meta.values()], dtype=str),
        )
        return path


def generator_meta(generator: GeneratorConfig) -> dict[str, str]:
    """The metadata entry recording the generator settings a set is made with (read back by
    :attr:`TestSet.generator_config`): a reset asking for other settings drops its own scenes."""
    return {"generator_config": json.dumps(asdict(generator), sort_keys=True)}


def load_test_set(path: str | Path) -> TestSet:
    """Read a test-set file; raises ``ValueError`` naming the file when it is not one."""
    with np.load(Path(path), allow_pickle=False) as data:
        meta = dict(zip(data["meta_keys"].tolist(), data["meta_values"].tolist()))
        if meta.get("format") != FORMAT:
            raise ValueError(f"{path}: not an {FORMAT} file")
        assets = data["assets"]
        return TestSet(
            name=meta["name"],
            num_objects=assets.shape[1],
            seeds=data["seeds"],
            assets=assets,
            positions=data["positions"],
            quats=data["quats"],
            targets=data["targets"],
            visible_fraction=data["visible_fraction"],
            meta=meta,
        )


def shipped_set_path(name: str, num_objects: int) -> Path:
    """Where the shipped set ``name`` at ``num_objects`` objects lives (it may not exist)."""
    return Path(str(resources.files("mpg_envs").joinpath("test_scenes", f"{name}_{num_objects}.npz")))


@functools.lru_cache(maxsize=8)
def find_test_set(name: str, num_objects: int) -> TestSet | None:
    """The shipped set ``name`` at ``num_objects`` objects, or ``None`` when none ships."""
    path = shipped_set_path(name, num_objects)
    return load_test_set(path) if path.is_file() else None
