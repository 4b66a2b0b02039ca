"""The content-addressed step store: Step results kept under a hash of everything they read.

Layout: ``<store>/<key[:2]>/<key>/`` is a one-checkpoint run folder in the format of
:mod:`schedules.execution.checkpoints` (``manifest.json`` whose fingerprint is the key, and
``steps/001.npz`` + ``steps/001.json``, data only, verified by SHA-256 when read).  Keys are
computed by :func:`schedules.execution.graph_tasks.step_key` / ``presolve_key``.

An entry is written into a temporary folder next to its place and renamed into place, so
concurrent workers that solve the same Step (two sweep variants sharing a branch) never
leave a half-written entry: the first rename wins, the other copy is dropped (both hold the
same data: the same inputs give the same result).  An entry that fails its SHA-256 check
is reported once on stderr and treated as missing (the Step is solved again and the entry
replaced).

Location: ``--store DIR`` / ``$COMPOSE_STEP_STORE``, else ``~/.cache/compose/steps``.  On
a cluster, point it at a shared file system so every worker sees every entry; a worker
that cannot see an entry only solves that Step again (same result).
"""
from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

from scenarios.atomic import atomic_dir
from scenarios.errors import InputError

from schedules.execution.checkpoints import CheckpointError, Manifest, read_checkpoint, write_checkpoint

__all__ = ["StepStore", "default_store"]

_FORMAT = 1
_NAME = "001"


def default_store() -> Path:
    """``$COMPOSE_STEP_STORE``, else ``~/.cache/compose/steps``."""
    env = os.environ.get("COMPOSE_STEP_STORE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "compose" / "steps"


class StepStore:
    """Get and put step results (dicts as checkpoints store them) by their content key."""

    def __init__(self, root: str | os.PathLike):
        self.root = Path(root)

    def _dir(self, key: str) -> Path:
        if len(key) != 64 or any(c not in "0123456789abcdef" for c in key):
            raise InputError(f"step store key {key!r} is not a SHA-256")
        return self.root / key[:2] / key

    def __contains__(self, key: str) -> bool:
        return (self._dir(key) / "manifest.json").is_file()

    def get(self, key: str) -> dict | None:
        """The stored result, verified, or None (absent or failing its check)."""
        d = self._dir(key)
        if not (d / "manifest.json").is_file():
            return None
        try:
            return read_checkpoint(Manifest.load(d), d, _NAME)
        except CheckpointError as exc:
            print(f"compose: step store entry {d} is damaged ({exc}); solving the step again", file=sys.stderr)
            return None

    def put(self, key: str, data: dict) -> Path:
        """Store ``data`` under ``key`` (atomically, see the module docstring)."""
        final = self._dir(key)
        if final.exists():  # a damaged entry (get() said so) or a concurrent writer's
            if self.get(key) is not None:
                return final
            shutil.rmtree(final, ignore_errors=True)
        with atomic_dir(final) as tmp:
            man = Manifest(tmp, _FORMAT, key)
            man.save()
            write_checkpoint(man, _NAME, data)
        return final
