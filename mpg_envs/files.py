"""Output files written whole or not at all: the one owner of how this project writes a file.

A file is written to a temporary file in its own folder, flushed and synced to the disk, then
swapped in with ``os.replace``: a reader sees the old file or the new one, never a part. When
the system refuses (a full disk, a read-only folder), the temporary file is removed, the old
file stays as it was, and :class:`WriteFailed` names the path and the system's reason on one
line.

- :func:`written_whole`: a context manager giving the temporary path to a writer that needs a
  path (``savefig``, ``np.savez``); the file is swapped in when the block ends without error.
- :func:`write_bytes_whole`, :func:`write_text_whole`: the same for bytes or text at hand.
- :func:`check_writable`, :func:`check_folder_writable`: before any work, whether a file may be
  written at a path at all (a folder that exists and takes a new file, not a device or other
  non-regular file), or files in a folder.
- :func:`same_file`: whether two paths name one file (an output that would overwrite an input).
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = [
    "WriteFailed",
    "check_folder_writable",
    "check_writable",
    "same_file",
    "write_bytes_whole",
    "write_text_whole",
    "written_whole",
]


class WriteFailed(OSError):
    """An output file could not be written; its old content (if any) is intact. The message is
    one line naming the path and the system's reason: ``cannot write 'out.json': No space left
    on device (the old file is kept)``."""

    def __init__(self, path: str | os.PathLike[str], reason: str) -> None:
        super().__init__(f"cannot write {str(path)!r}: {reason}")
        self.path, self.reason = str(path), reason

    def __reduce__(self) -> tuple[type, tuple[str, str]]:
        return type(self), (self.path, self.reason)


def _reason(exc: BaseException, folder: Path | None = None) -> str:
    """The system's reason of an ``OSError`` (``"No space left on device"``), else its text; a
    ``folder`` that exists yet has no room for a new file (``/proc``) is said so."""
    if isinstance(exc, OSError) and exc.errno == errno.ENOENT and folder is not None and folder.is_dir():
        return f"the folder {str(folder)!r} takes no new files"
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def _target(path: str | os.PathLike[str]) -> Path:
    """Where ``path`` writes: a symbolic link's target (the link stays a link)."""
    return Path(os.path.realpath(path))


def _mode_for(target: Path) -> int:
    """The mode the written file gets: the old file's, else what a plain ``open()`` gives (0666
    less the umask; a temporary file starts private, 0600)."""
    try:
        return stat.S_IMODE(target.stat().st_mode)
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def _refuse_non_regular(target: Path, path: str | os.PathLike[str]) -> None:
    """A :class:`WriteFailed` when ``target`` exists and is no regular file (a device, a folder, a pipe)."""
    try:
        mode = target.stat().st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise WriteFailed(path, _reason(exc)) from None
    if stat.S_ISDIR(mode):
        raise WriteFailed(path, "it is a folder; give a file path")
    if not stat.S_ISREG(mode):
        kind = "a character device" if stat.S_ISCHR(mode) else "a block device" if stat.S_ISBLK(mode) else "not a regular file"
        raise WriteFailed(path, f"it is {kind}; give the path of a regular file")


@contextlib.contextmanager
def written_whole(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path in ``path``'s folder (with ``path``'s suffix, so writers that read the
    format from it work) for the block to write; when the block ends without error the file
    is synced and replaces ``path`` at once. On any error the temporary file is removed and
    ``path`` is left as it was; an ``OSError`` becomes a one-line :class:`WriteFailed`.

    Raises:
        WriteFailed: the folder is missing or refuses the file, the disk is full, or ``path``
            is a folder, a device or another non-regular file.
    """
    target = _target(path)
    _refuse_non_regular(target, path)
    mode, kept = (
        _mode_for(target),
        " (the old file is kept)" if target.exists() else " (nothing written)",
    )
    try:
        fd, name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".tmp{target.suffix}", dir=target.parent)
    except OSError as exc:
        raise WriteFailed(path, _reason(exc, target.parent)) from None
    os.close(fd)
    tmp = Path(name)
    try:
        try:
            yield tmp
            with open(tmp, "rb+") as fh:  # what the writer wrote, on the disk before the swap
                os.fsync(fh.fileno())
            os.chmod(tmp, mode)
            os.replace(tmp, target)
        except OSError as exc:
            raise WriteFailed(path, f"{_reason(exc)}{kept}") from None
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    # The rename itself on the disk (best effort: not every system allows it).
    with contextlib.suppress(OSError):
        dir_fd = os.open(target.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)


def write_bytes_whole(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` whole or not at all (:func:`written_whole`); returns ``path``."""
    with written_whole(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
    return Path(path)


def write_text_whole(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` whole or not at all (:func:`written_whole`); returns ``path``."""
    return write_bytes_whole(path, text.encode(encoding))


def check_writable(path: str | os.PathLike[str]) -> None:
    """Whether a file can be written whole at ``path``, checked before any work: its folder
    exists and takes a new file (:func:`check_folder_writable`), and ``path`` is no folder,
    device or other non-regular file.

    Raises:
        WriteFailed: one line naming ``path`` and why it cannot be written.
    """
    target = _target(path)
    _refuse_non_regular(target, path)
    if not target.parent.is_dir():
        raise WriteFailed(path, f"the folder {str(Path(path).parent)!r} does not exist; create it first")
    if target.exists() and not os.access(target, os.W_OK):
        raise WriteFailed(path, "permission denied")
    try:
        check_folder_writable(target.parent)
    except WriteFailed as exc:
        raise WriteFailed(path, exc.reason) from None


def check_folder_writable(folder: str | os.PathLike[str]) -> None:
    """Whether files can be written in ``folder``, checked before any work by making and
    removing a one-byte file there (a read-only or full disk, ``/proc``, a folder without write
    permission all refuse it). A missing ``folder`` is checked at the nearest folder above it
    that exists (where the command would make it).

    Raises:
        WriteFailed: one line naming ``folder`` and why no file can be written in it.
    """
    folder = Path(folder)
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise WriteFailed(folder, f"{str(existing)!r} is a file, not a folder")
    try:
        with tempfile.NamedTemporaryFile(prefix=".write-check.", dir=existing) as probe:
            probe.write(b"\0")
            probe.flush()
            os.fsync(probe.fileno())
    except OSError as exc:
        raise WriteFailed(folder, _reason(exc, existing)) from None


def same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """Whether ``a`` and ``b`` name one existing file (through links or other spellings)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return os.path.realpath(a) == os.path.realpath(b) and os.path.exists(a)
