"""Atomic file writes: a final path holds its old content or all of the new, never part of it.

The one writer behind every output of a run — checkpoints and manifest
(:mod:`schedules.checkpoints`), the report, the report plots (:mod:`scenegraph.preview`),
the USD stage (:mod:`scenegraph.usd_export`) and BVH files (:mod:`scenegraph.bvh_export`).
A temporary file next to the final path (``.<name>.<random>.tmp``, or a temporary folder
for USD, whose exporter picks the format from the file name) is written, flushed and
``fsync``'ed, given the mode a new file gets under the umask (``mkstemp`` would leave
0600), and renamed over the final path with ``os.replace`` (atomic on POSIX within one
file system); then the folder is ``fsync``'ed so the rename survives a power cut.  A
SIGKILL at any moment leaves at most a temporary file (removed by the next run that holds
the run folder's lock, :func:`schedules.executor.prepare_run_dir`); any exception, or a
KeyboardInterrupt, removes it at once.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["file_mode", "atomic_write", "atomic_replace", "fsync_dir"]


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


def fsync_dir(folder: str | os.PathLike) -> None:
    """``fsync`` a folder (makes a rename in it durable); silently skipped where unsupported."""
    try:
        dfd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dfd)
    except OSError:
        pass
    finally:
        os.close(dfd)


def atomic_replace(tmp: str | os.PathLike, path: str | os.PathLike) -> Path:
    """Make the finished temporary file ``tmp`` (same folder or file system as ``path``)
    durable and give it the umask's mode, then rename it over ``path`` and sync the folder.
    The caller removes ``tmp`` if this raises."""
    path = Path(path)
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fchmod(fd, file_mode())
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    fsync_dir(path.parent if str(path.parent) else ".")
    return path


def atomic_write(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` so that ``path`` is either its old content or all of ``data``.

    The parent folder is created if needed.  On any failure (or a signal) the temporary file
    is removed and the exception propagates."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fchmod(fh.fileno(), file_mode())
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    fsync_dir(path.parent)
    return path
