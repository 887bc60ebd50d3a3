"""A run folder and who may write it: the folder itself, its lock, and whether a resume may go on.

- :func:`prepare_run_folder`: the run folder exists as a folder (a file at that path is an error)
  and is new, empty or a run of this project (:func:`is_run_folder`): a run rewrites and deletes
  files in its folder, so a folder holding anything else is refused, nothing in it touched.
- :class:`RunLock`: one process owns a run folder while it trains. The lock is an exclusive
  ``fcntl.flock`` on ``run.lock``, which names the owner (pid, host, start time); a second process
  refuses with :class:`RunFolderBusy` naming it. The kernel drops the lock when its owner dies
  (even by ``kill -9``), so a dead owner's ``run.lock`` is taken over without a word from the user.
  Within one process the lock is shared (a second learner on the same folder in the same process,
  as a resume test builds, is the same owner).
- :func:`resume_differences`: the settings of a saved run that differ from the ones asked for;
  a resume with any of them refuses unless asked to continue anyway (``mpg-train --resume-anyway``).
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from mpg_envs.files import WriteFailed, check_folder_writable

LOCK_NAME = "run.lock"

_HELD: dict[str, list[Any]] = {}  # resolved lock path -> [open file, holders in this process]


class RunFolderBusy(RuntimeError):
    """Another live process owns the run folder (its pid and host are in the message)."""


RUN_MARKS = (LOCK_NAME, "state/FORMAT", "state.old/FORMAT", "pipeline.json")
"""Files that only a run of this project writes in its folder: the lock (taken before anything
else is written, by a single stage and a pipeline alike) and a saved state or a pipeline's
record (runs older than the lock)."""

BEFORE_A_RUN = ("train.log",)
"""What a folder may hold before its run starts: ``mpg-train-runs`` opens its log there first."""


def is_run_folder(folder: str | Path) -> bool:
    """Whether ``folder`` may take a run: it is empty, holds only :data:`BEFORE_A_RUN`, or holds
    a run of this project (one of :data:`RUN_MARKS`), which it resumes."""
    folder = Path(folder)
    names = {p.name for p in folder.iterdir()}
    return names <= set(BEFORE_A_RUN) or any((folder / mark).is_file() for mark in RUN_MARKS)


def prepare_run_folder(out: str | Path) -> Path:
    """``out`` as a folder, made if missing; one that exists must be a run folder (:func:`is_run_folder`).

    Raises:
        ValueError: ``out`` (or a folder above it) is a file, ``out`` holds files of no run
            of this project (named; nothing in it is touched), or no file can be written there.
    """
    out = Path(out)
    for part in (out, *out.parents):
        if part.exists() and not part.is_dir():
            raise ValueError(f"run folder {str(out)!r}: {str(part)!r} is a file, not a folder; give --out a folder path")
    if out.is_dir() and not is_run_folder(out):
        held = sorted(p.name + ("/" if p.is_dir() else "") for p in out.iterdir())
        shown = ", ".join(held[:5]) + (f" and {len(held) - 5} more" if len(held) > 5 else "")
        raise ValueError(
            f"run folder {str(out)!r} is not empty and holds no run of this project ({shown}); "
            "a run would overwrite them: give a new or empty folder, or an earlier run's folder to resume it"
        )
    try:
        check_folder_writable(out)  # a read-only folder or disk, /proc: refused before any work
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # WriteFailed names why
        reason = exc.reason if isinstance(exc, WriteFailed) else exc.strerror or str(exc)
        raise ValueError(
            f"run folder {str(out)!r} cannot be written ({reason}); give --out a folder you may write in"
        ) from None
    return out


class RunLock:
    """The exclusive lock of one run folder (``run.lock``); release with :meth:`release`.

    Raises:
        RunFolderBusy: another process holds it (names its pid, host and start time).
    """

    def __init__(self, folder: str | Path) -> None:
        self.path = Path(folder) / LOCK_NAME
        self.key = str(self.path.resolve())
        self._released = False
        held = _HELD.get(self.key)
        if held is not None:
            held[1] += 1
            return
        handle = open(self.path, "a+")
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            owner = _owner(handle.read())
            handle.close()
            raise RunFolderBusy(
                f"run folder {str(self.path.parent)!r} is in use by {owner}; wait for it to finish, stop it, "
                "or give another --out"
            ) from None
        handle.seek(0)
        handle.truncate()
        handle.write(
            json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")})
        )
        handle.flush()
        _HELD[self.key] = [handle, 1]

    def release(self) -> None:
        """Let go of the lock (once; the last holder in this process unlocks the file)."""
        if self._released:
            return
        self._released = True
        held = _HELD.get(self.key)
        if held is None:
            return
        held[1] -= 1
        if held[1] == 0:
            del _HELD[self.key]
            held[0].close()  # closing the descriptor drops the flock

    def __enter__(self) -> RunLock:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.release()


def _owner(text: str) -> str:
    """``"process 123 on host 'box' (since ...)"`` from a ``run.lock``'s content."""
    try:
        info = json.loads(text)
        return f"process {info['pid']} on host {info['host']!r} (since {info['started']})"
    except (ValueError, KeyError, TypeError):
        return "another process"


def resume_differences(saved: Mapping[str, Any], asked: Mapping[str, Any], prefix: str = "") -> list[str]:
    """``"seed: saved 0, asked 1"`` for every setting that differs between a saved run's
    settings and the ones asked for (nested tables as ``stage.env_id``). A setting only one side
    has is left out: a run saved before the setting existed ran without it."""
    out = []
    for key in sorted(set(saved) & set(asked)):
        a, b = saved[key], asked[key]
        if isinstance(a, Mapping) and isinstance(b, Mapping):
            out += resume_differences(a, b, f"{prefix}{key}.")
        elif _plain(a) != _plain(b):
            out.append(f"{prefix}{key}: saved {a!r}, asked {b!r}")
    return out


def check_resume(out: Path, saved: Mapping[str, Any], asked: Mapping[str, Any], resume_anyway: bool = False) -> list[str]:
    """Whether the run saved in ``out`` (its ``saved`` settings) may continue with the ``asked``
    ones; returns their differences (:func:`resume_differences`; empty: the same run).

    Raises:
        ValueError: another env or trunk variant (never resumable), or any other difference
            without ``resume_anyway``; the message lists them.
    """
    saved_env = saved.get("stage", {}).get("env_id", saved.get("env_id"))
    asked_env = asked.get("stage", {}).get("env_id")
    if saved_env != asked_env or saved.get("variant") != asked.get("variant"):
        raise ValueError(
            f"{out} holds a run of {saved_env} ({saved.get('variant')}); "
            f"asked for {asked_env} ({asked.get('variant')}): use another --out"
        )
    changed = resume_differences(saved, asked)
    if changed and not resume_anyway:
        raise ValueError(
            f"{out} holds a run with other settings ({'; '.join(changed)}): give the run's own settings, "
            "another --out, or --resume-anyway to continue it with the new ones (the record keeps the new ones)"
        )
    return changed


def _plain(value: Any) -> Any:
    """Tuples as lists (JSON's view): a saved run's lists equal the asked tuples."""
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value
