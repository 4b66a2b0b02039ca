"""The one atomic file writer of compose: a file is either its old content or all of the new.

Every file compose writes (run-folder checkpoints and manifest, report, USD stages, BVH,
preview images and movies, style YAML, compiled kernels) goes through :func:`atomic_path`
or :func:`atomic_write`.  The contract (``tests/system/test_atomic.py``):

* the new content is written to a temporary file ``.<name>.<random><suffix>`` in the
  destination's folder, fsync'ed, given its mode, renamed over the destination (``os.replace``,
  atomic on POSIX within one file system), and the folder is fsync'ed so the rename survives
  a power cut;
* the mode is the one a new file gets under the process umask (0644 under umask 022;
  ``mkstemp`` alone would leave 0600), unless the caller gives one (0755 for a library);
* on any failure, including a signal or ``KeyboardInterrupt`` in the writing code, the
  temporary file is removed and the destination is untouched;
* a missing destination folder is an :class:`InputError` naming it (exit code 2), unless
  ``make_parents``; an operating-system failure is a :class:`WriteError`, which is both a
  :class:`ComposeError` (the CLI reports it, exit code 1) and an :class:`OSError`.

It lives in the language layer because that is the lowest layer that writes files (style
YAML); ``scenegraph`` and ``schedules`` import it from here.
"""
from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from scenarios.errors import ComposeError, InputError

__all__ = ["atomic_path", "atomic_write", "atomic_dir", "append_log", "file_mode", "WriteError"]


class WriteError(ComposeError, OSError):
    """A file could not be written (the operating system's error is the cause)."""


def file_mode() -> int:
    """Mode of a new regular file under the process umask (0644 under the usual umask 022)."""
    try:  # Linux: read the umask without changing it (os.umask would, briefly, for every thread)
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return 0o666 & ~int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    old = os.umask(0o022)
    os.umask(old)
    return 0o666 & ~old


def _fsync_dir(folder: Path) -> None:
    """Make a rename in ``folder`` durable (best effort: some file systems refuse)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextmanager
def atomic_path(path: str | os.PathLike, *, suffix: str = ".tmp", mode: int | None = None,
                make_parents: bool = False) -> Iterator[Path]:
    """Yield a temporary path next to ``path`` for the caller to write (by any means: a
    library that takes a file name, a compiler, …); when the block ends normally the file
    is fsync'ed, given ``mode`` (default :func:`file_mode`) and renamed over ``path``.

    ``suffix``: the temporary file's ending (give the destination's when the writer picks the
    format from it).  ``make_parents``: create the destination folder if it is missing."""
    path = Path(path)
    parent = path.parent
    if make_parents:
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise WriteError(f"could not write {path}: {exc}") from exc
    elif not parent.is_dir():
        raise InputError(f"cannot write {path}: directory {parent} does not exist")
    try:
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=parent)
    except OSError as exc:
        raise WriteError(f"could not write {path}: {exc}") from exc
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp, file_mode() if mode is None else mode)
        os.replace(tmp, path)
    except WriteError:
        raise
    except OSError as exc:
        raise WriteError(f"could not write {path}: {exc}") from exc
    finally:
        try:
            tmp.unlink()
        except FileNotFoundError:
            pass
    _fsync_dir(parent)


def atomic_write(path: str | os.PathLike, data: bytes | str, *, encoding: str = "utf-8",
                 mode: int | None = None, make_parents: bool = False) -> Path:
    """Write ``data`` (text is encoded with ``encoding``) to ``path`` atomically (see
    :func:`atomic_path`); returns the path."""
    raw = data.encode(encoding) if isinstance(data, str) else bytes(data)
    with atomic_path(path, mode=mode, make_parents=make_parents) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(raw)
    return Path(path)


@contextmanager
def atomic_dir(path: str | os.PathLike) -> Iterator[Path | None]:
    """Yield a temporary folder next to ``path`` for the caller to fill; when the block ends
    normally the folder is renamed to ``path`` (one ``rename``, atomic on POSIX) unless
    ``path`` exists by then (another writer was first: its folder is kept and this one is
    dropped). On any failure the temporary folder is removed. The parent is created."""
    import shutil

    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name[:12]}.", dir=path.parent))
    except OSError as exc:
        raise WriteError(f"could not write {path}: {exc}") from exc
    try:
        yield tmp
        if not path.exists():
            try:
                os.rename(tmp, path)
            except OSError:  # a concurrent writer renamed its copy first
                pass
            else:
                _fsync_dir(path.parent)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def append_log(path: str | os.PathLike):
    """Open a log file for appending (UTF-8, line-buffered). A log is a stream a reader may
    follow while it grows, so it is the one kind of file written in place, never atomically."""
    try:
        return open(path, "a", encoding="utf-8", buffering=1)
    except OSError as exc:
        raise WriteError(f"could not write {path}: {exc}") from exc
