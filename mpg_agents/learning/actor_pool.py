"""Where parallel actors run: one small interface, on Ray or on local processes.

An :class:`ActorPool` holds ``size`` :class:`~mpg_agents.learning.actors.Actor` objects, each in
its own process on one torch thread, and at most one request per actor in flight:
:meth:`~ActorPool.submit` asks actor ``i`` for a step, :meth:`~ActorPool.next_step` waits for
whichever finishes first. The learner asks again before it learns from a step, so actors step
their envs while it learns, and an actor never runs ahead of the learner by more than one step
(the replay ratio is the learner's to keep).

- :class:`RayActorPool`: Ray actors on a local Ray (one CPU each), or on the cluster at
  ``ray_address`` (every node needs this package installed and the run's checkpoint paths).
- :class:`ProcessActorPool`: stdlib ``multiprocessing`` processes (forked from a fresh server
  process, ``forkserver``), for machines without Ray; each talks to the learner through a pipe.

:func:`open_actor_pool` picks one (``TrainConfig.actor_backend``; ``auto``: Ray when it is
installed); :func:`check_actor_backend` says before any work whether the one asked for can run.
"""

from __future__ import annotations

import importlib.util
import logging
import multiprocessing as mp
import os
import signal
import traceback
from collections.abc import Sequence
from multiprocessing.connection import wait
from pathlib import Path
from typing import Any

from mpg_agents.learning.actors import Actor, ActorSpec, ActorStep, ActRequest
from mpg_agents.learning.train_config import TrainConfig
from mpg_envs.threads import WORKER_THREAD_ENV as THREAD_ENV
from mpg_envs.threads import one_thread_children, worker_init

RAY_INSTALL = "pip install 'mpg-grasp[ray]'"
"""How to get Ray (the package's extra)."""


def ray_installed() -> bool:
    """Whether ``import ray`` would work (without importing it)."""
    return importlib.util.find_spec("ray") is not None


def check_actor_backend(config: TrainConfig) -> str:
    """The backend ``config``'s actors run on (``"ray"`` or ``"processes"``).

    Raises:
        ValueError: the Ray backend (or a Ray address) is asked for and Ray is not installed.
    """
    backend = config.actor_backend
    if backend == "auto":
        backend = "ray" if ray_installed() or config.ray_address is not None else "processes"
    if backend == "ray" and not ray_installed():
        raise ValueError(
            f"training setting actor_backend 'ray' needs Ray, which is not installed: {RAY_INSTALL}, "
            "or train with actor_backend 'processes' (--actor-backend processes)"
        )
    return backend


class ActorPool:
    """``size`` actors, at most one request each in flight (see the module's docstring)."""

    size: int

    def submit(self, actor: int, request: ActRequest) -> None:
        """Ask ``actor`` (0-based) for one step; it must have none in flight."""
        raise NotImplementedError

    def next_step(self) -> ActorStep:
        """The first step an actor finishes (waits for one).

        Raises:
            RuntimeError: nothing is in flight, or an actor failed (its error is in the message).
        """
        raise NotImplementedError

    @property
    def in_flight(self) -> int:
        """Requests submitted and not yet returned by :meth:`next_step`."""
        raise NotImplementedError

    def close(self) -> None:
        """Stop every actor (steps in flight are dropped)."""
        raise NotImplementedError

    def __enter__(self) -> ActorPool:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _check_free(busy: Any, actor: int, size: int) -> None:
    if not 0 <= actor < size:
        raise ValueError(f"actor index must be in 0..{size - 1}, got {actor}")
    if actor in busy:
        raise RuntimeError(f"actor {actor} already has a step in flight")


# ------------------------------------------------------------------------------- processes
def _actor_process(spec: ActorSpec, conn: Any) -> None:
    """An actor's process: build the actor, then answer each request on ``conn`` until told to stop."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the learner's to handle: it saves, then stops us
    worker_init()
    actor = None
    try:
        actor = Actor.from_spec(spec)
        while True:
            try:
                request = conn.recv()
            except EOFError:  # the learner is gone
                return
            if request is None:
                return
            conn.send(("step", actor.step(request)))
    except Exception:
        try:
            conn.send(("error", traceback.format_exc()))
        except (BrokenPipeError, OSError):
            pass
    finally:
        if actor is not None:
            actor.close()


class ProcessActorPool(ActorPool):
    """Actors in local processes (no Ray), one torch/OpenMP thread each."""

    def __init__(self, specs: Sequence[ActorSpec]) -> None:
        # Forked from a fresh server process that has imported the actor's modules once (not from
        # the learner: no forked torch or MuJoCo state), so a second pool in this process starts fast.
        context = mp.get_context("forkserver")
        context.set_forkserver_preload(["mpg_agents.learning.actors"])
        self.size = len(specs)
        self._conns: list[Any] = []
        self._procs: list[Any] = []
        self._busy: set[int] = set()
        try:
            with one_thread_children():  # inherited by the children before they import torch
                for spec in specs:
                    parent, child = context.Pipe()
                    proc = context.Process(
                        target=_actor_process, args=(spec, child), name=f"mpg-actor-{spec.index}", daemon=True
                    )
                    proc.start()
                    child.close()
                    self._conns.append(parent)
                    self._procs.append(proc)
        except BaseException:
            self.close()
            raise

    def submit(self, actor: int, request: ActRequest) -> None:
        _check_free(self._busy, actor, self.size)
        self._conns[actor].send(request)
        self._busy.add(actor)

    @property
    def in_flight(self) -> int:
        return len(self._busy)

    def next_step(self) -> ActorStep:
        if not self._busy:
            raise RuntimeError("no actor has a step in flight")
        ready = wait([self._conns[i] for i in sorted(self._busy)])
        actor = self._conns.index(ready[0])
        self._busy.discard(actor)
        try:
            kind, value = self._conns[actor].recv()
        except EOFError:
            raise RuntimeError(f"actor {actor} died (exit code {self._procs[actor].exitcode})") from None
        if kind == "error":
            raise RuntimeError(f"actor {actor} failed:\n{value}")
        return value

    def close(self) -> None:
        for i, (conn, proc) in enumerate(zip(self._conns, self._procs)):
            if i in self._busy:  # mid-step: its result would be dropped anyway, and it would block sending it
                proc.terminate()
                continue
            try:
                conn.send(None)
            except (BrokenPipeError, OSError):
                pass
        for proc in self._procs:
            proc.join(timeout=10)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=10)
        for conn in self._conns:
            conn.close()
        self._conns, self._procs, self._busy = [], [], set()


# ------------------------------------------------------------------------------------- Ray
class _RayActor:
    """An :class:`~mpg_agents.learning.actors.Actor` as a Ray actor (one CPU, one thread)."""

    def __init__(self, spec: ActorSpec) -> None:
        worker_init()
        self.actor = Actor.from_spec(spec)

    def step(self, request: ActRequest) -> ActorStep:
        return self.actor.step(request)


class RayActorPool(ActorPool):
    """Ray actors on a local Ray (started here and shut down on :meth:`close`), or on the
    cluster at ``address`` (``"auto"``, ``"HOST:6379"``), or on the Ray already running."""

    def __init__(self, specs: Sequence[ActorSpec], address: str | None = None) -> None:
        import ray  # noqa: PLC0415 - Ray is an optional extra

        self._ray = ray
        self._started = False
        if not ray.is_initialized():
            env_vars = dict(THREAD_ENV)
            for key in ("MUJOCO_GL",):
                if key in os.environ:
                    env_vars[key] = os.environ[key]
            if address is None:
                # A local Ray's workers import this very package (a source checkout included).
                root = str(Path(__file__).resolve().parents[2])
                env_vars["PYTHONPATH"] = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)
                ray.init(
                    num_cpus=len(specs),
                    runtime_env={"env_vars": env_vars},
                    include_dashboard=False,
                    logging_level=logging.WARNING,
                )
            else:
                ray.init(address=address, runtime_env={"env_vars": env_vars}, logging_level=logging.WARNING)
            self._started = True
        remote = ray.remote(num_cpus=1)(_RayActor)
        self.size = len(specs)
        self._handles: list[Any] = [remote.remote(spec) for spec in specs]  # Ray actor handles
        self._pending: dict[Any, int] = {}

    def submit(self, actor: int, request: ActRequest) -> None:
        _check_free(set(self._pending.values()), actor, self.size)
        self._pending[self._handles[actor].step.remote(request)] = actor

    @property
    def in_flight(self) -> int:
        return len(self._pending)

    def next_step(self) -> ActorStep:
        if not self._pending:
            raise RuntimeError("no actor has a step in flight")
        ready, _ = self._ray.wait(list(self._pending), num_returns=1)
        actor = self._pending.pop(ready[0])
        try:
            return self._ray.get(ready[0])
        except Exception as exc:  # RayTaskError, RayActorError: the actor's own error inside
            raise RuntimeError(f"actor {actor} failed: {exc}") from exc

    def close(self) -> None:
        for handle in getattr(self, "_handles", []):
            self._ray.kill(handle)
        self._handles, self._pending = [], {}
        if self._started:
            self._ray.shutdown()
            self._started = False


def open_actor_pool(config: TrainConfig, specs: Sequence[ActorSpec]) -> ActorPool:
    """The pool of ``specs``' actors on ``config``'s backend (:func:`check_actor_backend`)."""
    if check_actor_backend(config) == "ray":
        return RayActorPool(specs, config.ray_address)
    return ProcessActorPool(specs)
