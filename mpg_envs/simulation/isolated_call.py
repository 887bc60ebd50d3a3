"""Calls into native code that may crash or hang, run in a worker process with a time limit.

Convex decomposition (``coacd``) is C++ that can segfault or never return on some inputs. A
crash there must not take the caller's interpreter (a training, an evaluation) down, so such
calls run in a child Python process: :class:`IsolatedWorker` starts it on first use (this
file run as a script, which imports only the standard library: nothing of the caller's
``__main__`` is re-run and no threads are forked), sends it ``"module:function"`` and the arguments (pickled),
and waits at most ``time_limit_s`` for the result. A crash (the worker dies, e.g. of SIGSEGV)
raises :class:`WorkerCrashedError`; a call that runs past its limit kills the worker and
raises :class:`WorkerTimeoutError`; an exception inside the call is re-raised as
:class:`WorkerCallError` with its type and message. The next call starts a fresh worker. The
worker imports modules with the caller's ``sys.path`` of the moment, so it runs the same code.
:class:`WorkerPool` holds several workers so that threads can run such calls in parallel.
"""

from __future__ import annotations

import atexit
import importlib
import os
import pickle
import queue
import signal
import struct
import subprocess
import sys
import threading
from collections.abc import Mapping
from typing import IO, Any

_HEADER = struct.Struct("<Q")  # message length prefix


class IsolatedCallError(RuntimeError):
    """A call run by :class:`IsolatedWorker` did not return a result."""


class WorkerCrashedError(IsolatedCallError):
    """The worker process died during the call (a native crash, e.g. SIGSEGV or abort)."""


class WorkerTimeoutError(IsolatedCallError):
    """The call ran past its time limit; the worker was killed."""


class WorkerCallError(IsolatedCallError):
    """The call raised a Python exception in the worker (``exc_type`` names its type,
    ``exc_message`` is its message)."""

    def __init__(self, message: str, exc_type: str, exc_message: str) -> None:
        super().__init__(message)
        self.exc_type = exc_type
        self.exc_message = exc_message


def _write_message(stream: IO[bytes], obj: Any) -> None:
    blob = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(blob)) + blob)
    stream.flush()


def _read_exact(stream: IO[bytes], size: int) -> bytes:
    chunks, left = [], size
    while left:
        chunk = stream.read(left)
        if not chunk:
            raise EOFError("worker pipe closed")
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def _read_message(stream: IO[bytes]) -> Any:
    (size,) = _HEADER.unpack(_read_exact(stream, _HEADER.size))
    return pickle.loads(_read_exact(stream, size))


def _describe_exit(returncode: int | None) -> str:
    if returncode is None:
        return "still running"
    if returncode < 0:
        try:
            return f"killed by signal {signal.Signals(-returncode).name}"
        except ValueError:
            return f"killed by signal {-returncode}"
    return f"exited with status {returncode}"


class IsolatedWorker:
    """One child Python process that runs calls one at a time (thread-safe; POSIX and Windows).

    ``env``: variables added to the child's environment (e.g. one compute thread each).
    """

    def __init__(self, env: Mapping[str, str] | None = None) -> None:
        self._env = dict(env) if env else None
        self._process: subprocess.Popen[bytes] | None = None
        self._owner = os.getpid()
        self._lock = threading.Lock()
        self.starts = 0
        """How many worker processes this object has started (a warm cache starts none)."""

    def call(self, target: str, args: tuple[Any, ...], time_limit_s: float) -> Any:
        """``target(*args)`` in the worker, where ``target`` is ``"module:function"``.

        Raises:
            ValueError: ``time_limit_s`` is not a positive number.
            WorkerCrashedError, WorkerTimeoutError, WorkerCallError: see the module text.
        """
        if not (isinstance(time_limit_s, (int, float)) and time_limit_s > 0):
            raise ValueError(f"time_limit_s must be a positive number of seconds, got {time_limit_s!r}")
        with self._lock:
            process = self._ensure_started()
            assert process.stdin is not None and process.stdout is not None
            stdout = process.stdout
            try:
                # The call is pickled apart: the worker unpickles it after taking on the path.
                _write_message(process.stdin, (list(sys.path), pickle.dumps((target, args), pickle.HIGHEST_PROTOCOL)))
            except (BrokenPipeError, OSError) as exc:
                self._stop()
                raise WorkerCrashedError(f"the worker process died before the call ({exc})") from exc
            replies: queue.Queue[tuple[str, Any]] = queue.Queue()

            def read_reply() -> None:
                try:
                    replies.put(("reply", _read_message(stdout)))
                except Exception as exc:  # EOF (the worker died) or a torn message
                    replies.put(("eof", exc))

            reader = threading.Thread(target=read_reply, daemon=True)
            reader.start()
            try:
                kind, reply = replies.get(timeout=time_limit_s)
            except queue.Empty:
                self._stop()  # the reader thread sees EOF and ends
                raise WorkerTimeoutError(f"{target} ran past its time limit of {time_limit_s:g} s") from None
            if kind == "eof":
                process.wait()
                code = process.returncode
                self._stop()
                raise WorkerCrashedError(f"the worker process running {target} died: {_describe_exit(code)}")
        status, *payload = reply
        if status == "ok":
            return payload[0]
        exc_type, message = payload
        raise WorkerCallError(f"{target} raised {exc_type}: {message}", exc_type, message)

    def close(self) -> None:
        """Stop the worker (a later call starts a new one)."""
        with self._lock:
            self._stop()

    def kill(self) -> None:
        """Kill the worker process now, from any thread, even while a call runs there (that call
        raises :class:`WorkerCrashedError`); a later call starts a new one."""
        process = self._process
        if process is not None and self._owner == os.getpid() and process.poll() is None:
            process.kill()

    def _ensure_started(self) -> subprocess.Popen[bytes]:
        if self._owner != os.getpid():
            # A forked child (a vector env's worker) must not share the parent's pipes.
            self._process, self._owner = None, os.getpid()
        if self._process is not None and self._process.poll() is None:
            return self._process
        # Each request carries the caller's sys.path, so the worker imports this very copy of
        # mpg_envs (and whatever the caller can import).
        self._process = subprocess.Popen(
            [sys.executable, os.path.abspath(__file__)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            env=None if self._env is None else {**os.environ, **self._env},
        )
        self.starts += 1
        return self._process

    def _stop(self) -> None:
        process, self._process = self._process, None
        if process is None or self._owner != os.getpid():
            return
        if process.poll() is None:
            process.kill()
        process.wait()
        for stream in (process.stdin, process.stdout):
            if stream is not None:
                try:
                    stream.close()
                except OSError:
                    pass


class WorkerPool:
    """Up to ``size`` :class:`IsolatedWorker` processes shared by threads: :meth:`call` runs on
    a free one, so up to ``size`` calls run at once, each isolated and timed as by
    :meth:`IsolatedWorker.call`.

    The pool grows on demand: a call takes a free worker, and creates a new one (``env`` as for
    :class:`IsolatedWorker`; it starts on its first call) only when none has come free within
    ``grow_after_s`` seconds and fewer than ``size`` exist. So quick calls stay on the workers
    already running (a process start costs about a second of imports), while slow ones spread
    out. ``first`` (e.g. :func:`shared_worker`, already warm) is the pool's first worker; it is
    not stopped by :meth:`close`, which stops the others (also on leaving a ``with`` block).
    """

    def __init__(
        self,
        size: int,
        env: Mapping[str, str] | None = None,
        *,
        first: IsolatedWorker | None = None,
        grow_after_s: float = 0.0,
    ) -> None:
        if isinstance(size, bool) or not isinstance(size, int) or size < 1:
            raise ValueError(f"size must be a positive integer (worker processes), got {size!r}")
        if not (isinstance(grow_after_s, (int, float)) and grow_after_s >= 0):
            raise ValueError(f"grow_after_s must be a number of seconds >= 0, got {grow_after_s!r}")
        self.size = size
        """The most workers the pool holds."""
        self._env = env
        self._first = first
        self._grow_after_s = float(grow_after_s)
        self._workers: list[IsolatedWorker] = [] if first is None else [first]
        self._free: queue.Queue[IsolatedWorker] = queue.Queue()
        self._lock = threading.Lock()
        self._killed = False
        for worker in self._workers:
            self._free.put(worker)

    @property
    def workers(self) -> int:
        """How many workers the pool has made use of so far (``first`` included)."""
        return len(self._workers)

    @property
    def starts(self) -> int:
        """Worker processes started so far, all workers together (``first``'s included)."""
        return sum(worker.starts for worker in self._workers)

    def call(self, target: str, args: tuple[Any, ...], time_limit_s: float) -> Any:
        """``target(*args)`` on a free worker; see :meth:`IsolatedWorker.call`.

        Raises:
            WorkerCrashedError: also when the pool was killed (:meth:`kill`).
        """
        worker = self._take()
        try:
            if self._killed:
                raise WorkerCrashedError(f"the worker pool was stopped before {target} could run")
            return worker.call(target, args, time_limit_s)
        finally:
            self._free.put(worker)

    def close(self) -> None:
        """Stop the workers the pool created (a later call starts one again)."""
        for worker in self._workers:
            if worker is not self._first:
                worker.close()

    def kill(self) -> None:
        """Kill every worker process now, ``first`` included (:meth:`IsolatedWorker.kill`): calls
        running end with :class:`WorkerCrashedError`, later ones raise it at once. For stopping
        threads that wait on the pool (an interrupted load); :meth:`close` still follows."""
        self._killed = True
        for worker in list(self._workers):
            worker.kill()

    def _take(self) -> IsolatedWorker:
        if self._workers:
            try:
                return self._free.get(timeout=self._grow_after_s) if self._grow_after_s else self._free.get_nowait()
            except queue.Empty:
                pass
        with self._lock:
            if len(self._workers) < self.size:
                worker = IsolatedWorker(self._env)
                self._workers.append(worker)
                return worker
        return self._free.get()

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_SHARED: IsolatedWorker | None = None
_SHARED_LOCK = threading.Lock()


def shared_worker() -> IsolatedWorker:
    """The process-wide worker (started on its first call, stopped at interpreter exit)."""
    global _SHARED
    with _SHARED_LOCK:
        if _SHARED is None:
            _SHARED = IsolatedWorker()
            atexit.register(_SHARED.close)
        return _SHARED


def _serve() -> None:
    """The worker's loop: read (sys.path, pickled (target, args)), reply ("ok", result) or
    ("error", type, message)."""
    requests = os.fdopen(os.dup(0), "rb")
    replies = os.fdopen(os.dup(1), "wb")
    # Native libraries print to fd 1; keep the reply pipe clean by sending fd 1 to stderr.
    os.dup2(2, 1)
    while True:
        try:
            path, call = _read_message(requests)
        except EOFError:
            return
        try:
            sys.path[:] = path
            target, args = pickle.loads(call)
            module_name, _, function_name = target.partition(":")
            function = getattr(importlib.import_module(module_name), function_name)
            reply: tuple[Any, ...] = ("ok", function(*args))
        except Exception as exc:  # reported to the caller with its type
            reply = ("error", type(exc).__name__, str(exc))
        _write_message(replies, reply)


if __name__ == "__main__":
    _serve()
