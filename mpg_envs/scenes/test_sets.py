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
import zipfile
import zlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from mpg_envs.grid.workspace import Workspace
from mpg_envs.scenes.generators import GeneratorConfig
from mpg_envs.scenes.scene_file import SceneFile, SceneObject
from mpg_envs.simulation.assets import ObjectAsset
from mpg_envs.simulation.families import FAMILY_SEED_RANGES
from mpg_envs.simulation.mujoco_version import MUJOCO_KEY, mujoco_major, recorded_mujoco, running_mujoco

GENERATOR_VERSION = 1
"""Version of scene generation the shipped sets were made with."""

TEST_SEEDS: range = FAMILY_SEED_RANGES["test"]
"""The held-out test env seeds (500000-699999; tuning seeds start at 700000): every test set's
seeds lie here, and a reset of any other seed never reads a test-set file."""

TEST_SEED_START = TEST_SEEDS.start
"""The held-out test seeds start here (Table I's evaluations use 500000 onwards)."""

VISIBLE_FRACTION_TOLERANCE = 1e-4
"""How far a test scene's visible fraction at reset may lie from the one its set records. The
sets store it as float32 (about 1e-8 off) and a reset rebuilds the scene bit for bit, so an
unchanged set matches to that; one pixel of a target's footprint (at most a few thousand
pixels) is more than this, and a target moved 1 cm changes it by several hundredths."""

ACROSS_MUJOCO_TOLERANCE = 0.02
"""The same on another MuJoCo major version than the set was made with (its ``mujoco_version``):
the scene is placed bit for bit, but MuJoCo 4's ray casts hit a few pixels at mesh edges
otherwise, which moved the fraction by up to 0.011 over 260 held-out scenes of the sets made
with MuJoCo 3.17; a target moved 1 cm still changes it by 0.04-0.08."""

LFS_POINTER_START = b"version https://git-lfs.github.com/spec/"
"""How a Git LFS pointer file begins (what a clone without ``git lfs`` holds instead of a set)."""

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


class TestSetError(RuntimeError, ValueError):
    """A shipped test set that cannot be used as it is (stale, or its scenes changed): bad
    input, as a ``ValueError`` is (the command lines report it on one line)."""

    __test__ = False  # not a pytest test class


class StaleTestSetError(TestSetError):
    """A test set was made by another scene generator (code, parameters or version) than the
    running code's: its scenes are not the ones this code drops for its seeds."""


class ChangedTestSetError(TestSetError):
    """A test scene, rebuilt at its reset, is not the scene its set was made with: the target's
    visible fraction there is not the recorded one (the file was changed since it was made)."""


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
                raise ValueError(
                    f"test set {self.name!r}: {field} has shape {np.shape(getattr(self, field))}, expected {shape}"
                )
        object.__setattr__(self, "_index", {int(seed): k for k, seed in enumerate(self.seeds)})

    def __len__(self) -> int:
        return len(self.seeds)

    def has_seed(self, seed: int) -> bool:
        """Whether ``seed`` is one of the set's scenes."""
        return int(seed) in self._index  # type: ignore[attr-defined]

    def scene(self, seed: int, object_set: Sequence[ObjectAsset]) -> SceneFile:
        """The scene of ``seed`` with its assets taken from ``object_set`` (by name)."""
        if not self.has_seed(seed):
            raise KeyError(
                f"seed {seed} is not in test set {self.name!r} ({len(self)} scenes, seeds {self.seeds[0]}..{self.seeds[-1]})"
            )
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

    @property
    def made_with_mujoco(self) -> str:
        """The MuJoCo version the set was made with (``"3.x"`` for a set that records none)."""
        return recorded_mujoco({MUJOCO_KEY: self.meta.get("mujoco_version")})

    def visible_fraction_tolerance(self) -> float:
        """:data:`VISIBLE_FRACTION_TOLERANCE` on the MuJoCo major version the set was made with,
        :data:`ACROSS_MUJOCO_TOLERANCE` on another."""
        same = mujoco_major(self.made_with_mujoco) == mujoco_major(running_mujoco())
        return VISIBLE_FRACTION_TOLERANCE if same else ACROSS_MUJOCO_TOLERANCE

    def check_visible_fraction(self, seed: int, measured: float | None) -> None:
        """Raise :class:`ChangedTestSetError`, naming the set, the seed, both values and both
        MuJoCo versions, unless ``measured`` (the target's visible fraction in the rebuilt scene
        of ``seed``, on a clean ray cast) is the recorded one within
        :meth:`visible_fraction_tolerance`."""
        recorded = float(self.visible_fraction[self._index[int(seed)]])  # type: ignore[attr-defined]
        tolerance = self.visible_fraction_tolerance()
        if measured is not None and abs(measured - recorded) <= tolerance:
            return
        shown = "none (no target in view)" if measured is None else f"{measured:.6f}"
        raise ChangedTestSetError(
            f"test set {self.name}_{self.num_objects}: the scene of seed {seed} is not the one the set was made with "
            f"(the target's visible fraction at reset is {shown}, the set records {recorded:.6f}, tolerance "
            f"{tolerance:g}); restore the file {self.name}_{self.num_objects}.npz (reinstall the "
            f"package, or `git checkout -- mpg_envs/test_scenes/{self.name}_{self.num_objects}.npz`) or regenerate it "
            f"with `python benchmarks/make_test_sets.py --envs {self.meta.get('env_id', '<its env id>')} --objects "
            f"{self.num_objects}` (the set was made with MuJoCo "
            f"{self.made_with_mujoco}, this is MuJoCo {running_mujoco()})"
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
    """Read a test-set file; raises ``ValueError`` naming the file when it is not one (a Git
    LFS pointer, a truncated or foreign file, missing arrays, seeds outside :data:`TEST_SEEDS`)."""
    path = Path(path)
    with open(path, "rb") as file:
        head = file.read(len(LFS_POINTER_START))
    if head == LFS_POINTER_START:
        raise ValueError(
            f"{path}: a Git LFS pointer, not the test set itself; fetch the file with `git lfs pull` "
            f"(in the repository's folder), or reinstall the package"
        )
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in _ARRAYS if key in data.files}
    except FileNotFoundError:
        raise
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError) as exc:
        raise ValueError(
            f"{path}: not a readable {FORMAT} file (truncated or damaged: {exc}); reinstall the package or regenerate it"
        ) from exc
    except ValueError as exc:  # numpy's: a file that is no .npz (it would read it as a pickle), object arrays
        raise ValueError(f"{path}: not an {FORMAT} file ({exc})") from exc
    missing = [key for key in _ARRAYS if key not in arrays]
    if missing:
        raise ValueError(f"{path}: not an {FORMAT} file (no {', '.join(missing)})")
    meta = dict(zip(arrays["meta_keys"].tolist(), arrays["meta_values"].tolist()))
    if meta.get("format") != FORMAT or "name" not in meta:
        raise ValueError(f"{path}: not an {FORMAT} file")
    seeds, assets = arrays["seeds"], arrays["assets"]
    if seeds.ndim != 1 or assets.ndim != 2:
        raise ValueError(f"{path}: not an {FORMAT} file (seeds of shape {seeds.shape}, assets of shape {assets.shape})")
    outside = [int(seed) for seed in seeds if int(seed) not in TEST_SEEDS]
    if outside:
        raise ValueError(f"{path}: seeds {outside[:3]} lie outside the test seeds {TEST_SEEDS.start}-{TEST_SEEDS.stop - 1}")
    try:
        return TestSet(
            name=meta["name"],
            num_objects=assets.shape[1],
            seeds=seeds,
            assets=assets,
            positions=arrays["positions"],
            quats=arrays["quats"],
            targets=arrays["targets"],
            visible_fraction=arrays["visible_fraction"],
            meta=meta,
        )
    except ValueError as exc:  # arrays of mismatched shapes
        raise ValueError(f"{path}: {exc}") from exc


_ARRAYS = ("seeds", "assets", "positions", "quats", "targets", "visible_fraction", "meta_keys", "meta_values")
"""The arrays of a test-set file (what :meth:`TestSet.save` writes)."""


def shipped_set_path(name: str, num_objects: int) -> Path:
    """Where the shipped set ``name`` at ``num_objects`` objects lives (it may not exist)."""
    return Path(str(resources.files("mpg_envs").joinpath("test_scenes", f"{name}_{num_objects}.npz")))


@functools.lru_cache(maxsize=8)
def find_test_set(name: str, num_objects: int) -> TestSet | None:
    """The shipped set ``name`` at ``num_objects`` objects, or ``None`` when none ships."""
    path = shipped_set_path(name, num_objects)
    return load_test_set(path) if path.is_file() else None
