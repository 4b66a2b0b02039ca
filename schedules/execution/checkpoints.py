"""Run-folder files: atomic writes, data-only checkpoints verified by SHA-256, the run lock.

A run folder (``runs/<name>`` by default) holds

* ``manifest.json``: ``{"format", "fingerprint", "checkpoints": {file name: SHA-256}}``;
  it is rewritten (atomically) after every checkpoint and is what *commits* a checkpoint;
* ``steps/<name>.npz`` + ``steps/<name>.json`` per finished Step (``001`` …) and per
  kinematic pre-solve (``000_<character>``): every numpy array of the Step's result in the
  ``.npz`` (read with ``allow_pickle=False``: no object arrays, no code), everything else
  (statuses, iteration counts, violations, timing, footsteps as plain numbers) in the JSON,
  where an array is a reference ``{"$array": "a3"}`` into the ``.npz``;
* ``.lock``: the run lock (``fcntl.flock``), holding the owner's PID.

Nothing in a run folder is ever unpickled or executed.  On ``--resume`` a committed
checkpoint whose files are missing, truncated or edited (SHA-256 differs from the
manifest's), or that belongs to another run or step, is an :class:`InputError` naming the
file; checkpoint files that the manifest does not list (the process was killed between
writing them and committing them) are ignored and their Step solved again.
"""
from __future__ import annotations

import errno
import fcntl
import hashlib
import io
import json
import os
import re
import zipfile
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np

from scenarios.atomic import atomic_write as _atomic_write
from scenarios.errors import ComposeError, InputError, Location
from scenegraph.model.footsteps import Footstep

__all__ = ["atomic_write", "atomic_write_text", "sha256_bytes", "sha256_file",
           "CheckpointError", "Manifest", "encode", "decode", "write_checkpoint", "read_checkpoint",
           "checkpoint_names", "read_all", "RunLock", "RunFolderBusy", "LOCK_NAME", "MAX_CHECKPOINT_BYTES"]

LOCK_NAME = ".lock"
MAX_CHECKPOINT_BYTES = 512 * 1024 * 1024  # a checkpoint file larger than this is not read
_NAME = re.compile(r"^(?:\d{3}|000_[A-Za-z_][A-Za-z0-9_]{0,63})$")
_HEX64 = re.compile(r"^[0-9a-f]{64}$")


# --- atomic files: the one writer of scenarios/atomic.py -----------------------------------------

def atomic_write(path: str | os.PathLike, data: bytes) -> Path:
    """:func:`scenarios.atomic.atomic_write` into a run folder (created if needed)."""
    return _atomic_write(path, data, make_parents=True)


def atomic_write_text(text: str, path: str | os.PathLike) -> Path:
    """:func:`atomic_write` of UTF-8 text (argument order of the executor's old helper)."""
    return _atomic_write(path, text, make_parents=True)


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: Path, limit: int = MAX_CHECKPOINT_BYTES) -> tuple[str, bytes]:
    """(SHA-256, content) of a file of at most ``limit`` bytes."""
    with open(path, "rb") as fh:
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise CheckpointError(f"checkpoint file is larger than {limit} bytes", path)
    return sha256_bytes(data), data


# --- encoding: plain data + arrays ----------------------------------------------------------------

class CheckpointError(InputError):
    """A checkpoint that cannot be trusted: missing, truncated, edited or foreign (exit code 2)."""

    def __init__(self, message: str, path: str | os.PathLike | None = None):
        super().__init__(f"--resume: checkpoint rejected: {message}; it was not loaded. Remove the run folder "
                         "(or run without --resume) to solve again", Location(str(path) if path else None))


_FOOTSTEP_FIELDS = tuple(f.name for f in fields(Footstep))


def encode(obj: Any, arrays: dict[str, np.ndarray]) -> Any:
    """JSON-able form of a Step result; numpy arrays go to ``arrays`` (key ``a<n>``) and are
    referenced as ``{"$array": key}``; tuples become ``{"$tuple": [...]}``, footsteps
    ``{"$footstep": {field: value}}``."""
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, (int, np.integer)) and not isinstance(obj, np.bool_):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj)
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind not in "biuf":
            raise TypeError(f"checkpoint arrays must be numeric or bool, got dtype {obj.dtype}")
        key = f"a{len(arrays)}"
        arrays[key] = np.ascontiguousarray(obj)
        return {"$array": key}
    if isinstance(obj, Footstep):
        return {"$footstep": {k: encode(getattr(obj, k), arrays) for k in _FOOTSTEP_FIELDS}}
    if isinstance(obj, tuple):
        return {"$tuple": [encode(v, arrays) for v in obj]}
    if isinstance(obj, list):
        return [encode(v, arrays) for v in obj]
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, str) or k.startswith("$"):
                raise TypeError(f"checkpoint dict keys must be strings not starting with '$', got {k!r}")
            out[k] = encode(v, arrays)
        return out
    raise TypeError(f"cannot store a {type(obj).__name__} in a checkpoint")


def decode(obj: Any, arrays: dict[str, np.ndarray], where: Path | None = None, depth: int = 0) -> Any:
    """Inverse of :func:`encode`; anything else is a :class:`CheckpointError`."""
    if depth > 64:
        raise CheckpointError("nested too deeply", where)
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    if isinstance(obj, list):
        return [decode(v, arrays, where, depth + 1) for v in obj]
    if not isinstance(obj, dict):
        raise CheckpointError(f"unexpected JSON value of type {type(obj).__name__}", where)
    tags = [k for k in obj if k.startswith("$")]
    if not tags:
        return {k: decode(v, arrays, where, depth + 1) for k, v in obj.items()}
    if len(obj) != 1:
        raise CheckpointError(f"malformed tagged value {sorted(obj)}", where)
    tag, val = next(iter(obj.items()))
    if tag == "$array":
        if not isinstance(val, str) or val not in arrays:
            raise CheckpointError(f"reference to a missing array {val!r}", where)
        return arrays[val]
    if tag == "$tuple":
        if not isinstance(val, list):
            raise CheckpointError("malformed tuple", where)
        return tuple(decode(v, arrays, where, depth + 1) for v in val)
    if tag == "$footstep":
        if not isinstance(val, dict) or set(val) != set(_FOOTSTEP_FIELDS):
            raise CheckpointError("malformed footstep", where)
        d = {k: decode(v, arrays, where, depth + 1) for k, v in val.items()}
        try:
            for k in ("position", "heel", "ball"):
                if d[k] is not None:
                    d[k] = tuple(float(x) for x in d[k])
                    if len(d[k]) != 2:
                        raise ValueError(f"{k} needs two numbers")
            for k in ("t0", "t1", "heading"):
                d[k] = float(d[k])
            if not isinstance(d["free"], bool):
                raise ValueError("free must be true or false")
            return Footstep(**d)
        except (TypeError, ValueError) as exc:
            raise CheckpointError(f"malformed footstep: {exc}", where) from None
    raise CheckpointError(f"unknown tag {tag!r}", where)


# --- manifest ---------------------------------------------------------------------------------------

class Manifest:
    """The run folder's ``manifest.json``: format, run fingerprint, committed checkpoint hashes."""

    def __init__(self, run_dir: Path, fmt: int, fingerprint: str, checkpoints: dict[str, str] | None = None):
        self.run_dir = Path(run_dir)
        self.format = fmt
        self.fingerprint = fingerprint
        self.checkpoints: dict[str, str] = dict(checkpoints or {})

    @property
    def path(self) -> Path:
        return self.run_dir / "manifest.json"

    def save(self) -> None:
        atomic_write_text(json.dumps({"format": self.format, "fingerprint": self.fingerprint,
                                      "checkpoints": dict(sorted(self.checkpoints.items()))}, indent=1) + "\n",
                          self.path)

    @classmethod
    def load(cls, run_dir: Path) -> dict:
        """The raw manifest data, checked for shape (an InputError naming the file otherwise)."""
        path = Path(run_dir) / "manifest.json"
        try:
            raw = path.read_bytes()
            if len(raw) > 16 * 1024 * 1024:
                raise ValueError("larger than 16 MB")
            data = json.loads(raw.decode("utf-8"))
        except (OSError, ValueError) as exc:
            raise InputError(f"--resume: cannot read the run manifest: {exc}", Location(str(path))) from None
        if not isinstance(data, dict) or not isinstance(data.get("fingerprint"), str):
            raise InputError("--resume: not a compose run manifest (no fingerprint)", Location(str(path)))
        ck = data.get("checkpoints", {})
        if not isinstance(ck, dict) or not all(isinstance(k, str) and isinstance(v, str) and _HEX64.match(v)
                                               for k, v in ck.items()):
            raise InputError("--resume: malformed 'checkpoints' in the run manifest (file name -> SHA-256)",
                             Location(str(path), field="checkpoints"))
        return data


# --- checkpoints --------------------------------------------------------------------------------------

def _check_name(name: str) -> None:
    if not _NAME.match(name):
        raise ValueError(f"bad checkpoint name {name!r}")


def write_checkpoint(manifest: Manifest, name: str, data: dict) -> None:
    """Write ``steps/<name>.npz`` and ``steps/<name>.json`` atomically, then commit them in
    the manifest with their SHA-256 (a kill before the commit leaves an uncommitted
    checkpoint, which ``--resume`` ignores)."""
    _check_name(name)
    arrays: dict[str, np.ndarray] = {}
    body = encode(data, arrays)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    npz = buf.getvalue()
    doc = {"format": manifest.format, "fingerprint": manifest.fingerprint, "name": name,
           "npz_sha256": sha256_bytes(npz), "data": body}
    text = json.dumps(doc, allow_nan=True, separators=(",", ":")).encode("utf-8")
    steps = manifest.run_dir / "steps"
    if f"{name}.json" in manifest.checkpoints or f"{name}.npz" in manifest.checkpoints:
        # overwriting a committed checkpoint: uncommit it first, or a kill between the file
        # writes and the commit would leave the manifest naming the old hashes of new files
        manifest.checkpoints.pop(f"{name}.json", None)
        manifest.checkpoints.pop(f"{name}.npz", None)
        manifest.save()
    atomic_write(steps / f"{name}.npz", npz)
    atomic_write(steps / f"{name}.json", text)
    manifest.checkpoints[f"{name}.npz"] = sha256_bytes(npz)
    manifest.checkpoints[f"{name}.json"] = sha256_bytes(text)
    manifest.save()


def checkpoint_names(run_dir: Path) -> list[str]:
    """Names of the checkpoints present in ``run_dir/steps`` (committed or not), sorted."""
    steps = Path(run_dir) / "steps"
    return sorted(p.stem for p in steps.glob("*.json") if _NAME.match(p.stem)) if steps.is_dir() else []


def read_checkpoint(manifest: Manifest | dict, run_dir: Path, name: str) -> dict | None:
    """The data of a committed checkpoint, verified, or None when ``name`` is not committed.

    ``manifest``: a :class:`Manifest` or the dict of :meth:`Manifest.load`.  Raises
    :class:`CheckpointError` (naming the file) when a committed file is missing, its SHA-256
    differs from the manifest's, or it belongs to another run folder or format."""
    _check_name(name)
    if isinstance(manifest, Manifest):
        ck, fp, fmt = manifest.checkpoints, manifest.fingerprint, manifest.format
    else:
        ck, fp, fmt = manifest.get("checkpoints", {}), manifest["fingerprint"], manifest.get("format")
    jname, zname = f"{name}.json", f"{name}.npz"
    if jname not in ck and zname not in ck:
        return None
    steps = Path(run_dir) / "steps"
    jpath, zpath = steps / jname, steps / zname
    got = {}
    for fname, path in ((jname, jpath), (zname, zpath)):
        if fname not in ck:
            raise CheckpointError(f"{fname} is not recorded in the manifest", path)
        try:
            h, content = sha256_file(path)
        except FileNotFoundError:
            raise CheckpointError("file is missing (the manifest lists it)", path) from None
        except OSError as exc:
            raise CheckpointError(f"cannot read it: {exc}", path) from None
        if h != ck[fname]:
            raise CheckpointError(f"SHA-256 {h[:16]}… differs from the manifest's {ck[fname][:16]}… "
                                  "(truncated, edited or from another run)", path)
        got[fname] = content
    try:
        doc = json.loads(got[jname].decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise CheckpointError(f"not JSON: {exc}", jpath) from None
    if not isinstance(doc, dict) or set(doc) != {"format", "fingerprint", "name", "npz_sha256", "data"}:
        raise CheckpointError("not a compose checkpoint", jpath)
    if doc["fingerprint"] != fp or doc["format"] != fmt or doc["name"] != name:
        raise CheckpointError(f"belongs to another run (fingerprint {doc['fingerprint']!r}, name {doc['name']!r}; "
                              f"this run: {fp!r}, {name!r})", jpath)
    if doc["npz_sha256"] != sha256_bytes(got[zname]):
        raise CheckpointError("its arrays file is not the one it was written with", zpath)
    try:
        with np.load(io.BytesIO(got[zname]), allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, KeyError) as exc:  # object arrays (pickles): ValueError
        raise CheckpointError(f"unreadable arrays: {exc}", zpath) from None
    for k, a in arrays.items():
        if a.dtype.kind not in "biuf":
            raise CheckpointError(f"array {k} has dtype {a.dtype}", zpath)
    data = decode(doc["data"], arrays, jpath)
    if not isinstance(data, dict):
        raise CheckpointError("checkpoint data is not a mapping", jpath)
    return data


def read_all(run_dir: str | os.PathLike) -> dict[str, dict]:
    """{checkpoint name: data} of every committed checkpoint of a run folder, verified
    (for tests and tools that inspect a finished run)."""
    run_dir = Path(run_dir)
    man = Manifest.load(run_dir)
    names = sorted({k.rsplit(".", 1)[0] for k in man.get("checkpoints", {}) if _NAME.match(k.rsplit(".", 1)[0])})
    return {n: read_checkpoint(man, run_dir, n) for n in names}


# --- the run lock -----------------------------------------------------------------------------------

class RunFolderBusy(InputError):
    """Another live process holds the run folder's lock (exit code 2)."""


_HELD: dict[str, list] = {}  # realpath of a lock file -> [fd, depth] (re-entrant within a process)


class RunLock:
    """Exclusive lock of a run folder: ``<run_dir>/.lock`` locked with ``fcntl.flock`` and
    holding the owner's PID.  The kernel drops the lock when its process dies (even by
    SIGKILL), so a lock file left by a dead process does not block.  Re-entrant within one
    process (the CLI holds it around the run and the report; the executor takes it again)."""

    def __init__(self, run_dir: str | os.PathLike):
        self.run_dir = Path(run_dir)
        self.path = self.run_dir / LOCK_NAME
        self._key: str | None = None

    def acquire(self) -> RunLock:
        self.run_dir.mkdir(parents=True, exist_ok=True)
        key = os.path.realpath(self.path)
        if key in _HELD:
            _HELD[key][1] += 1
            self._key = key
            return self
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise ComposeError(f"cannot lock the run folder: {exc}", Location(str(self.path))) from None
            holder = self._holder()
            raise RunFolderBusy(f"the run folder {self.run_dir} is in use by another compose run"
                                f"{f' (pid {holder})' if holder else ''}; wait for it to finish, stop it, or "
                                "use another --run-dir", Location(str(self.path))) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        _HELD[key] = [fd, 1]
        self._key = key
        return self

    def _holder(self) -> int | None:
        try:
            text = self.path.read_text(encoding="ascii", errors="replace").strip()
            return int(text) if text.isdigit() else None
        except OSError:
            return None

    def release(self) -> None:
        key, self._key = self._key, None
        if key is None or key not in _HELD:
            return
        _HELD[key][1] -= 1
        if _HELD[key][1] > 0:
            return
        fd, _ = _HELD.pop(key)
        try:
            os.ftruncate(fd, 0)  # the file stays (unlinking it races with a waiting process)
        except OSError:
            pass
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
