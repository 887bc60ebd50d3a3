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
    """One child Python process that runs calls one at a time (thread-safe; POSIX and Windows)."""

    def __init__(self) -> None:
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
            try:
                # The call is pickled apart: the worker unpickles it after taking on the path.
                _write_message(process.stdin, (list(sys.path), pickle.dumps((target, args), pickle.HIGHEST_PROTOCOL)))
            except (BrokenPipeError, OSError) as exc:
                self._stop()
                raise WorkerCrashedError(f"the worker process died before the call ({exc})") from exc
            replies: queue.Queue[tuple[str, Any]] = queue.Queue()

            def read_reply() -> None:
                try:
                    replies.put(("reply", _read_message(process.stdout)))
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

    def _ensure_started(self) -> subprocess.Popen[bytes]:
        if self._owner != os.getpid():
            # A forked child (a vector env's worker) must not share the parent's pipes.
            self._process, self._owner = None, os.getpid()
        if self._process is not None and self._process.poll() is None:
            return self._process
        # Each request carries the caller's sys.path, so the worker imports this very copy of
        # mpg_envs (and whatever the caller can import).
        self._process = subprocess.Popen(
            [sys.executable, os.path.abspath(__file__)], stdin=subprocess.PIPE, stdout=subprocess.PIPE
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
