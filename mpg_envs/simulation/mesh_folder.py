"""A folder of mesh files as objects (:func:`load_mesh_folder`): in parallel, nothing lost to one bad mesh.

Each file goes through :class:`~mpg_envs.simulation.meshes.MeshJob`. The slow step, its convex
decomposition, runs for several files at once, in the worker processes of a
:class:`~mpg_envs.simulation.isolated_call.WorkerPool` of at most the cores free now
(:func:`mpg_envs.threads.num_threads`): the shared worker first, and another (on one compute
thread) whenever a mesh has waited :data:`GROW_AFTER_S` for a free one, so quick meshes cost no
process starts and slow ones spread over the cores. Each file's result depends on that file
alone, and the objects and warnings are made afterwards in file-name order, so a parallel load
gives what a serial one gives. A mesh that cannot be loaded (its
decomposition crashed, failed or ran out of time with no fallback, or the file is unusable) is
skipped with a warning naming it and why; the result lists the skipped files
(:attr:`MeshFolderObjects.skipped`), and a folder where every mesh fails is an error.
"""

from __future__ import annotations

import os
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from mpg_envs.simulation.assets import DEFAULT_FRICTION, TABLEAU_10, WOOD_DENSITY, ObjectAsset
from mpg_envs.simulation.geometry_cache import CachedSolid
from mpg_envs.simulation.isolated_call import WorkerPool, shared_worker
from mpg_envs.simulation.meshes import DEFAULT_TIME_LIMIT_S, MESH_SUFFIXES, CoacdParams, Fit, MeshJob, MeshLoadError
from mpg_envs.threads import WORKER_THREAD_ENV, num_threads

__all__ = ["GROW_AFTER_S", "MeshFolderObjects", "SkippedMesh", "load_mesh_folder"]

GROW_AFTER_S = 0.5
"""Seconds a mesh waits for a busy worker before another worker process is started for it (a
start costs about a second of imports; a quick mesh takes well under 0.1 s in a running one)."""


@dataclass(frozen=True)
class SkippedMesh:
    """A mesh file of a folder that could not be loaded, and why."""

    path: str
    reason: str
    """The :class:`~mpg_envs.simulation.meshes.MeshLoadError` message (it names the file)."""


class MeshFolderObjects(list[ObjectAsset]):
    """The objects of a mesh folder (a list, in file-name order) and the files it skipped."""

    skipped: tuple[SkippedMesh, ...]
    """The meshes that could not be loaded, in file-name order (each was warned about)."""

    def __init__(self, objects: list[ObjectAsset], skipped: tuple[SkippedMesh, ...] = ()) -> None:
        super().__init__(objects)
        self.skipped = tuple(skipped)


def load_mesh_folder(
    folder: str | os.PathLike[str],
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
    scale: float = 1.0,
    mass: float | None = None,
    *,
    fit: Fit = "none",
    density: float = WOOD_DENSITY,
    friction: float = DEFAULT_FRICTION,
    coacd_params: CoacdParams | None = None,
    time_limit_s: float = DEFAULT_TIME_LIMIT_S,
    workers: int | None = None,
) -> MeshFolderObjects:
    """Every OBJ/STL mesh of a folder (not recursive) as an object, sorted by file name.

    Each file is loaded as by :func:`~mpg_envs.simulation.meshes.load_mesh_file` (same
    arguments; ``time_limit_s`` applies to each mesh), up to ``workers`` decompositions at
    once. The object's name is the file stem; its colour is ``TABLEAU_10[i % 10]`` for the
    ``i``-th file in sorted order, skipped files included (colours or textures carried by the
    files are ignored, so every set looks alike and masks stay easy to tell apart). A mesh that
    cannot be loaded is skipped with a ``RuntimeWarning`` naming the file and why, and listed in
    the result's ``skipped``.

    Args:
        workers: worker processes decomposing meshes at once, at most one per file; ``None``
            means :func:`mpg_envs.threads.num_threads` (``MPG_NUM_THREADS`` or
            ``OMP_NUM_THREADS`` when set, else the cores free now). With 1, meshes are
            decomposed one by one in the shared worker.

    Returns:
        The objects (a list) with ``skipped``, the files left out.

    Raises:
        FileNotFoundError: ``folder`` does not exist.
        NotADirectoryError: ``folder`` is not a folder.
        ValueError: no mesh in the folder, or a bad argument (named).
        MeshLoadError: no mesh of the folder could be loaded (names the folder and the files).
    """
    root = Path(folder).expanduser()
    if not root.exists():
        raise FileNotFoundError(f"mesh folder {str(root)!r} does not exist")
    if not root.is_dir():
        raise NotADirectoryError(f"mesh folder {str(root)!r} is not a folder")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers must be a positive integer or None (the free cores), got {workers!r}")
    files = sorted(
        (p for p in root.iterdir() if p.suffix.lower() in MESH_SUFFIXES and not p.name.startswith(".")),
        key=lambda p: p.name,
    )
    if not files:
        raise ValueError(f"mesh folder {str(root)!r} holds no {'/'.join(MESH_SUFFIXES)} files")
    jobs: list[MeshJob | MeshLoadError] = []
    for path in files:  # a bad argument raises ValueError here, before any decomposition
        try:
            jobs.append(
                MeshJob.prepare(
                    path,
                    seed,
                    cache_dir,
                    scale,
                    mass,
                    fit=fit,
                    density=density,
                    friction=friction,
                    coacd_params=coacd_params,
                    time_limit_s=time_limit_s,
                )  # fmt: skip
            )
        except MeshLoadError as exc:
            jobs.append(exc)
    solids = _solids(jobs, workers)
    objects: list[ObjectAsset] = []
    skipped: list[SkippedMesh] = []
    for index, (path, job, solid) in enumerate(zip(files, jobs, solids, strict=True)):
        try:
            if isinstance(solid, MeshLoadError):
                raise solid
            assert isinstance(job, MeshJob)
            objects.append(job.asset(solid, rgba=TABLEAU_10[index % len(TABLEAU_10)]))
        except MeshLoadError as exc:
            warnings.warn(f"skipping a mesh of folder {str(root)!r}: {exc}", RuntimeWarning, stacklevel=2)
            skipped.append(SkippedMesh(str(path), str(exc)))
    if not objects:
        names = ", ".join(Path(s.path).name for s in skipped)
        raise MeshLoadError(
            f"mesh folder {str(root)!r}: none of its {len(files)} meshes could be loaded ({names}); "
            f"the first: {skipped[0].reason}"
        )
    return MeshFolderObjects(objects, tuple(skipped))


def _solids(jobs: list[MeshJob | MeshLoadError], workers: int | None) -> list[CachedSolid | MeshLoadError]:
    """Each job's solid (or its error), in the jobs' order: in parallel when more than one worker."""

    def solid(job: MeshJob | MeshLoadError, worker: WorkerPool | None) -> CachedSolid | MeshLoadError:
        if isinstance(job, MeshLoadError):
            return job
        try:
            return job.solid(shared_worker() if worker is None else worker)
        except MeshLoadError as exc:
            return exc

    todo = sum(isinstance(job, MeshJob) for job in jobs)
    size = min(num_threads(workers), todo)
    if size <= 1:
        return [solid(job, None) for job in jobs]
    # The shared worker (warm after a first load) goes first; others start only when meshes
    # wait for it (GROW_AFTER_S): none for a folder found in the cache or made of quick meshes.
    pool = WorkerPool(size, WORKER_THREAD_ENV, first=shared_worker(), grow_after_s=GROW_AFTER_S)
    threads = ThreadPoolExecutor(size)
    try:
        return list(threads.map(lambda job: solid(job, pool), jobs))
    except BaseException:  # an interrupt (Ctrl-C): end the running decompositions now
        threads.shutdown(wait=False, cancel_futures=True)
        pool.kill()
        raise
    finally:
        threads.shutdown(wait=True)
        pool.close()
