"""How many compute threads a process should use: the cores actually free, not all of them.

Users run evaluations, vector envs and trainings side by side. A process that starts as many
busy threads as the machine has cores, while other processes use them too, gets its threads
descheduled in the middle of parallel regions; the others then wait (or spin) at the barrier
and a decision costs several times its fair share (4x was measured on 2 shared cores). Three
measures keep the slowdown close to fair sharing:

- :func:`choose_threads`: threads from the cores this process may use (its CPU affinity)
  minus the load (:func:`load_average`), at least one; an argument, ``MPG_NUM_THREADS`` or
  ``OMP_NUM_THREADS`` overrides it. Entry points (the CLIs, the demo) call
  :func:`set_torch_threads` once at start;
- :func:`use_passive_openmp_wait`: OpenMP threads sleep when idle instead of spinning
  (``OMP_WAIT_POLICY=PASSIVE``; read once, when torch loads OpenMP);
- :func:`worker_init`: one thread in each worker process (vector envs, evaluation workers),
  which get their parallelism from the number of processes.

Nothing here imports torch: :func:`set_torch_threads` imports it when called.

Environment variables, read and written:

- ``MPG_NUM_THREADS`` (read): fixes the thread count of :func:`num_threads` (torch threads of
  the command lines, ray-cast threads of an env); unset or empty means automatic.
- ``OMP_NUM_THREADS`` (read): an explicit value is respected when ``MPG_NUM_THREADS`` is unset.
- ``OMP_WAIT_POLICY`` (written by :func:`use_passive_openmp_wait`, which ``import mpg_agents``
  calls): set to ``PASSIVE`` only when unset; set it yourself before importing to choose
  another policy. ``import mpg_envs`` does not touch it.
- :func:`worker_init` sets ``OMP_NUM_THREADS=1`` and ``MPG_NUM_THREADS=1`` in the worker
  process it runs in (and ``OMP_WAIT_POLICY=PASSIVE`` when unset); it is meant for worker
  processes only.
"""

from __future__ import annotations

import math
import os
import statistics
import sys
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

THREADS_ENV = "MPG_NUM_THREADS"
"""Environment variable that fixes the thread count (a positive integer)."""

WORKER_THREAD_ENV: dict[str, str] = {
    "OMP_NUM_THREADS": "1",
    "MPG_NUM_THREADS": "1",
    "OMP_WAIT_POLICY": "PASSIVE",
    "MKL_NUM_THREADS": "1",
}
"""What a worker process needs before it imports torch to compute on one passive thread (what
:func:`worker_init` sets once it runs); :func:`one_thread_children` puts it in place while
workers start, so they inherit it."""


@contextmanager
def one_thread_children() -> Iterator[None]:
    """Set :data:`WORKER_THREAD_ENV` in this process's environment while worker processes are
    started inside the block (they inherit it before they import torch), then restore every
    variable as it was (unset ones unset)."""
    saved = {k: os.environ.get(k) for k in WORKER_THREAD_ENV}
    os.environ.update(WORKER_THREAD_ENV)
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def choose_threads(cores: int, load: float, max_threads: int | None = None, machine_cores: int | None = None) -> int:
    """Threads for ``cores`` usable cores while the machine's load is ``load``.

    The free cores are ``machine_cores - load`` (``machine_cores`` defaults to ``cores``; the
    load is machine-wide, so a process pinned to 2 of 16 cores counts the other 14 too),
    rounded to the nearest integer (half up); the result is at least 1 and at most ``cores``
    (and ``max_threads`` when given).

    >>> choose_threads(2, 0.1), choose_threads(2, 1.2), choose_threads(2, 7.0), choose_threads(16, 3.0)
    (2, 1, 1, 13)
    >>> choose_threads(2, 12.0, machine_cores=16), choose_threads(2, 15.0, machine_cores=16)
    (2, 1)
    """
    if cores < 1:
        raise ValueError(f"cores must be >= 1, got {cores!r}")
    if not math.isfinite(load) or load < 0:
        raise ValueError(f"load must be a finite number >= 0, got {load!r}")
    if max_threads is not None and max_threads < 1:
        raise ValueError(f"max_threads must be >= 1 or None, got {max_threads!r}")
    if machine_cores is not None and machine_cores < cores:
        raise ValueError(f"machine_cores ({machine_cores}) must be >= cores ({cores})")
    free = math.floor((cores if machine_cores is None else machine_cores) - load + 0.5)
    upper = cores if max_threads is None else min(cores, max_threads)
    return max(1, min(upper, free))


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity on Linux, else the CPU count)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # macOS, Windows
        return os.cpu_count() or 1


def runnable_now(samples: int = 5, interval_s: float = 0.005) -> float | None:
    """Other threads runnable right now machine-wide (``/proc/loadavg``), the median of a few
    samples so a momentary burst does not count; ``None`` where ``/proc`` is absent."""
    counts = []
    for i in range(samples):
        try:
            with open("/proc/loadavg") as fh:
                running = int(fh.read().split()[3].split("/")[0])
        except (OSError, ValueError, IndexError):
            return None
        counts.append(max(0, running - 1))  # this thread, reading, is one of them
        if i + 1 < samples:
            time.sleep(interval_s)
    return float(statistics.median(counts))


def load_average() -> float:
    """The load other work puts on the machine now: the threads runnable right now where Linux
    tells (:func:`runnable_now`), else the 1-minute load average.

    The 1-minute average lags a minute both ways: it misses a busy process started a second
    ago and still counts one that ended half a minute ago (both seen when measuring).
    """
    now = runnable_now()
    if now is not None:
        return now
    try:
        return os.getloadavg()[0]
    except (AttributeError, OSError):
        return 0.0


def requested_threads(environ: Mapping[str, str] | None = None) -> int | None:
    """The thread count fixed by ``MPG_NUM_THREADS``, or ``None`` when it is unset or empty."""
    value = (os.environ if environ is None else environ).get(THREADS_ENV, "").strip()
    if not value:
        return None
    try:
        n = int(value)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"{THREADS_ENV} must be a positive integer (or unset for automatic), got {value!r}")
    return n


def num_threads(requested: int | None = None) -> int:
    """The thread count to use: ``requested``, else ``MPG_NUM_THREADS``, else an explicit
    ``OMP_NUM_THREADS`` (a worker's or the user's), else the free cores (:func:`choose_threads`)."""
    if requested is not None:
        if isinstance(requested, bool) or not isinstance(requested, int) or requested < 1:
            raise ValueError(f"num_threads must be a positive integer or None (automatic), got {requested!r}")
        return requested
    fixed = requested_threads()
    if fixed is not None:
        return fixed
    omp = os.environ.get("OMP_NUM_THREADS", "").strip()
    if omp.isdigit() and int(omp) >= 1:
        return int(omp)
    cores = available_cores()
    return choose_threads(cores, load_average(), machine_cores=max(cores, os.cpu_count() or cores))


def set_torch_threads(requested: int | None = None) -> int:
    """Set torch's intra-op threads to :func:`num_threads` (``requested``) and return the count."""
    import torch  # noqa: PLC0415 - an optional extra (agents): mpg_envs never imports it

    n = num_threads(requested)
    if torch.get_num_threads() != n:
        torch.set_num_threads(n)
    return n


def use_passive_openmp_wait() -> None:
    """Make idle OpenMP threads sleep rather than spin, unless the user chose a policy.

    OpenMP reads ``OMP_WAIT_POLICY`` when its runtime starts (when torch is imported), so this
    must run before that; afterwards it changes nothing for this process (its children inherit
    it).
    """
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def worker_init(*_: object) -> None:
    """One compute thread in this worker process (a vector env's or an evaluation worker).

    Usable as ``initializer=`` of ``multiprocessing``/``concurrent.futures`` pools (it ignores
    arguments). Sets ``OMP_NUM_THREADS=1`` and ``MPG_NUM_THREADS=1`` for anything started
    later in the process, and torch's threads to 1 if torch is already imported.
    """
    os.environ["OMP_NUM_THREADS"] = "1"
    os.environ[THREADS_ENV] = "1"
    use_passive_openmp_wait()
    torch = sys.modules.get("torch")
    if torch is not None and torch.get_num_threads() != 1:
        torch.set_num_threads(1)
