"""Compile CasADi functions to C once, cache the shared library on disk, load it back.

``compiled(f)`` returns a :class:`casadi.Function` that computes the same as ``f`` with
generated C code: the first call for a given function writes C, compiles it with
``gcc -O1 -fPIC -shared`` and stores the library in the cache; later calls (in this or any
other process) load it without compiling.  -O1, not -O3: on the Jacobian of the 35-DOF
inverse dynamics gcc -O3 needed minutes where -O1 needs seconds for nearly the same speed.

Cache key: sha256 of ``f.serialize()``, the CasADi version, the compiler command and the
flags; so a change to the character model, the dynamics or the toolchain gives a new file.
Cache directory: ``$COMPOSE_CACHE_DIR``, else ``~/.cache/compose``.  Libraries are
compiled into a temporary file in that directory and renamed into place, so several
processes may compile the same function at once and none ever loads half a file.

If no compiler is found or compilation fails, ``compiled`` warns once (one line,
:class:`CodegenWarning`) and returns ``f`` itself: the CasADi virtual machine computes the
same numbers, only slower.  ``COMPOSE_NO_CODEGEN=1`` disables code generation.  The
compiler is ``$CC`` if set, else ``gcc``, else ``cc``.
"""
from __future__ import annotations

import functools
import hashlib
import os
import shlex
import shutil
import subprocess
import tempfile
import time
import warnings
from pathlib import Path

import casadi as ca

from scenarios.atomic import atomic_path

__all__ = ["compiled", "cache_dir", "library_path", "id_function", "id_jacobian_function", "CodegenWarning", "STATS"]

FLAGS = ("-O1", "-fPIC", "-shared")

# Counters for tests and benchmarks: libraries compiled, libraries loaded from the disk
# cache, and the wall time (s) of the last compilation.
STATS = {"compiled": 0, "loaded": 0, "last_compile_s": 0.0}
_loaded: dict[str, ca.Function] = {}  # library path -> loaded function (no repeated dlopen in a process)


class CodegenWarning(RuntimeWarning):
    """Code generation was not possible; the CasADi VM is used instead."""


def cache_dir() -> Path:
    """Directory of compiled libraries: ``$COMPOSE_CACHE_DIR`` or ``~/.cache/compose``."""
    env = os.environ.get("COMPOSE_CACHE_DIR")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "compose"


def _compiler() -> list[str] | None:
    """The compiler command as a list, or None when none is on the PATH."""
    cc = os.environ.get("CC")
    candidates = [shlex.split(cc)] if cc else [["gcc"], ["cc"]]
    for cmd in candidates:
        if cmd and shutil.which(cmd[0]):
            return cmd
    return None


def _fallback(f: ca.Function, why: str) -> ca.Function:
    warnings.warn(f"compose: {why}; using the CasADi VM for {f.name()!r} (slower)", CodegenWarning, stacklevel=3)
    return f


def _key(f: ca.Function, cc: list[str], with_jacobian: bool = False) -> str:
    h = hashlib.sha256()
    for part in (f.serialize(), ca.__version__, " ".join(cc), " ".join(FLAGS), "jac" if with_jacobian else ""):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


def library_path(f: ca.Function, name: str | None = None, with_jacobian: bool = False) -> Path | None:
    """Where the compiled library of ``f`` is (or would be) cached; None without a compiler."""
    cc = _compiler()
    if cc is None:
        return None
    return cache_dir() / f"{name or f.name()}-{_key(f, cc, with_jacobian)[:24]}.so"


def compiled(f: ca.Function, name: str | None = None, with_jacobian: bool = False) -> ca.Function:
    """``f`` as compiled C code loaded with ``casadi.external`` (cached on disk; see module doc).

    ``name`` only labels the cached file (default ``f.name()``).  ``with_jacobian`` also
    compiles ``f``'s Jacobian, so CasADi can take *first* derivatives of the loaded function
    (gradients, Jacobians); second derivatives of a compiled function are not available.
    Returns ``f`` itself when code generation is disabled or impossible.
    """
    if os.environ.get("COMPOSE_NO_CODEGEN", "") not in ("", "0"):
        return f
    lib = library_path(f, name, with_jacobian)
    if lib is None:
        return _fallback(f, "no C compiler found (set CC or install gcc)")
    if str(lib) in _loaded:
        return _loaded[str(lib)]
    if not lib.exists():
        try:
            lib.parent.mkdir(parents=True, exist_ok=True)
            _build(f, _compiler(), lib, with_jacobian)
        except (OSError, subprocess.SubprocessError) as exc:
            detail = str(exc).strip().splitlines()
            return _fallback(f, f"compiling {lib.name} failed ({detail[-1] if detail else type(exc).__name__})")
    else:
        STATS["loaded"] += 1
    try:
        g = ca.external(f.name(), str(lib))
    except RuntimeError as exc:  # e.g. a library from another machine in a shared cache
        return _fallback(f, f"loading {lib} failed ({str(exc).strip().splitlines()[0]})")
    _loaded[str(lib)] = g
    return g


def _build(f: ca.Function, cc: list[str], lib: Path, with_jacobian: bool = False) -> None:
    """Generate C for ``f`` and compile it to ``lib`` via a temporary file and a rename."""
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="compose-cg-") as tmp:
        src = f"{f.name()}.c"
        gen = ca.CodeGenerator(src, {"with_header": False})
        gen.add(f)
        if with_jacobian:
            gen.add(f.jacobian())
        gen.generate(tmp + os.sep)
        with atomic_path(lib, mode=0o755) as partial:
            res = subprocess.run([*cc, *FLAGS, os.path.join(tmp, src), "-o", str(partial), "-lm"],
                                 capture_output=True, text=True)
            if res.returncode != 0:
                raise subprocess.SubprocessError(f"{cc[0]} exited with {res.returncode}: {res.stderr.strip()}")
    STATS["compiled"] += 1
    STATS["last_compile_s"] = time.perf_counter() - t0


# --- inverse dynamics of a character -------------------------------------------------------

def _id_sx(ch):
    from scenegraph.model.body import N_DOF
    from scenegraph.model.dynamics import rnea

    q, qd, qdd = (ca.SX.sym(n, N_DOF) for n in ("q", "qd", "qdd"))
    return q, qd, qdd, rnea(ch, q, qd, qdd)


@functools.lru_cache(maxsize=8)
def id_function(ch, compile: bool = True) -> ca.Function:
    """Inverse dynamics ``(q, qd, qdd) -> tau`` (35 each) of a character, compiled if possible."""
    q, qd, qdd, tau = _id_sx(ch)
    f = ca.Function("compose_id", [q, qd, qdd], [tau], ["q", "qd", "qdd"], ["tau"])
    return compiled(f) if compile else f


@functools.lru_cache(maxsize=8)
def id_jacobian_function(ch, compile: bool = True) -> ca.Function:
    """``(q, qd, qdd) -> d tau / d(q, qd, qdd)`` (35×105, sparse) of a character, compiled if possible."""
    q, qd, qdd, tau = _id_sx(ch)
    jac = ca.jacobian(tau, ca.vertcat(q, qd, qdd))
    f = ca.Function("compose_id_jac", [q, qd, qdd], [jac], ["q", "qd", "qdd"], ["jac"])
    return compiled(f) if compile else f
