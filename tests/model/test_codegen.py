"""Code generation: compiled == VM, the disk cache is hit, the VM fallback works."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import warnings

import casadi as ca
import numpy as np
import pytest

from conftest import character
from pinocchio_model import random_states
from scenegraph.model import codegen
from scenegraph.model.codegen import CodegenWarning, compiled


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty cache directory, codegen enabled, default compiler, nothing loaded in-process."""
    d = tmp_path / "cache"
    monkeypatch.setenv("COMPOSE_CACHE_DIR", str(d))
    monkeypatch.delenv("COMPOSE_NO_CODEGEN", raising=False)
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setattr(codegen, "_loaded", {})
    return d


def small(scale: float = 1.0) -> ca.Function:
    x, y = ca.SX.sym("x", 3), ca.SX.sym("y", 2)
    return ca.Function("small", [x, y], [scale * ca.sin(x) * y[0] + x ** 2, ca.dot(x, x) * ca.exp(y[1])])


def _libs(d):
    return sorted(p.name for p in d.iterdir()) if d.exists() else []


def test_compiled_equals_vm(cache):
    f = small()
    g = compiled(f)
    assert g.class_name() == "External"
    rng = np.random.default_rng(0)
    X, Y = rng.normal(size=(3, 50)), rng.normal(size=(2, 50))
    for a, b in zip(f.map(50)(X, Y), g.map(50)(X, Y)):
        assert np.allclose(np.array(a), np.array(b), rtol=1e-14, atol=1e-14)
    assert [p.endswith(".so") for p in _libs(cache)] == [True]


def test_second_call_hits_the_cache(cache):
    f = small()
    before = dict(codegen.STATS)
    compiled(f)
    assert codegen.STATS["compiled"] == before["compiled"] + 1
    (lib,) = cache.iterdir()
    stamp = lib.stat().st_mtime_ns
    # same process: the loaded function is reused
    assert compiled(small()) is compiled(f)
    # "new process": nothing loaded yet, the library comes from disk, nothing is compiled
    codegen._loaded.clear()
    g = compiled(small())
    assert codegen.STATS["compiled"] == before["compiled"] + 1
    assert codegen.STATS["loaded"] == before["loaded"] + 1
    assert lib.stat().st_mtime_ns == stamp and _libs(cache) == [lib.name]
    assert float(g([1, 2, 3], [0.5, 0.1])[1]) == pytest.approx(14 * np.exp(0.1))
    # a different function is a different library
    compiled(small(2.0))
    assert codegen.STATS["compiled"] == before["compiled"] + 2 and len(_libs(cache)) == 2


def _run(code: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env, capture_output=True, text=True,
                          timeout=120)


def test_cache_is_shared_between_processes(cache, adult):
    """Two processes compiling the same function at once both succeed and leave one library;
    a third process loads the character's inverse dynamics without compiling."""
    env = dict(os.environ, COMPOSE_CACHE_DIR=str(cache))
    code = """
        import casadi as ca
        from scenegraph.model import codegen
        x = ca.SX.sym("x", 4)
        g = codegen.compiled(ca.Function("race", [x], [ca.cumsum(ca.sin(x))]))
        assert g.class_name() == "External", g
        print(float(g([1, 2, 3, 4])[-1]))
    """
    procs = [subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert all(p.returncode == 0 for p in procs), outs
    assert [float(o[0]) for o in outs] == pytest.approx([np.sum(np.sin([1, 2, 3, 4]))] * 2)
    assert [n.startswith("race-") and n.endswith(".so") for n in _libs(cache)] == [True]  # no temporary left over

    f = compiled(codegen.id_function(adult, compile=False))  # compiled here ...
    assert f.class_name() == "External"
    res = _run("""
        from scenegraph.model import codegen
        from scenegraph.model.body import make_character
        f = codegen.id_function(make_character())
        print(f.class_name(), codegen.STATS["compiled"], codegen.STATS["loaded"])
    """, env)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["External", "0", "1"]  # ... and only loaded there


def test_id_function_matches_vm(adult):
    """The compiled inverse dynamics (through the default cache) equals the symbolic one."""
    f_c, f_vm = codegen.id_function(adult), codegen.id_function(adult, compile=False)
    assert f_vm.class_name() == "SXFunction"
    q, qd, qdd = random_states(adult, 20, seed=4)
    a = np.array(f_c.map(20)(q.T, qd.T, qdd.T))
    b = np.array(f_vm.map(20)(q.T, qd.T, qdd.T))
    assert np.allclose(a, b, rtol=1e-12, atol=1e-9)
    assert codegen.id_function(character()) is f_c  # cached per character


def test_with_jacobian_gives_first_derivatives(cache):
    f = small()
    X, Y = ca.MX.sym("X", 3), ca.MX.sym("Y", 2)
    jac = lambda g: ca.Function("J", [X, Y], [ca.jacobian(g(X, Y)[1], ca.vertcat(X, Y))])  # noqa: E731
    with pytest.raises(RuntimeError):
        jac(compiled(f))([1, 2, 3], [0.5, 0.1])  # a plain external has no derivatives
    g = compiled(f, with_jacobian=True)
    assert g.class_name() == "External"
    assert np.allclose(np.array(jac(g)([1, 2, 3], [0.5, 0.1])), np.array(jac(f)([1, 2, 3], [0.5, 0.1])), rtol=1e-14)


def test_falls_back_without_compiler(cache, monkeypatch, tmp_path):
    empty = tmp_path / "empty-bin"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty))
    f = small()
    with pytest.warns(CodegenWarning, match="no C compiler found"):
        g = compiled(f)
    assert g is f and _libs(cache) == []
    assert codegen.library_path(f) is None


def test_falls_back_when_cc_is_missing(cache, monkeypatch):
    monkeypatch.setenv("CC", "/nonexistent/bin/gcc")
    f = small()
    with pytest.warns(CodegenWarning, match="no C compiler"):
        assert compiled(f) is f


def test_falls_back_when_compilation_fails(cache, monkeypatch):
    monkeypatch.setenv("CC", "false")  # exists, always fails
    f = small()
    with pytest.warns(CodegenWarning, match="failed") as rec:
        assert compiled(f) is f
    assert len(rec) == 1 and "\n" not in str(rec[0].message)  # one line
    assert _libs(cache) == []  # no half-written library, no temporary left over


def test_disabled_by_environment(cache, monkeypatch):
    monkeypatch.setenv("COMPOSE_NO_CODEGEN", "1")
    f = small()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert compiled(f) is f
    assert _libs(cache) == []


def test_cache_key_includes_compiler_and_cache_dir(cache, monkeypatch, tmp_path):
    f = small()
    default = codegen.library_path(f)
    assert default.parent == cache
    monkeypatch.setenv("CC", "gcc -fno-fast-math")
    assert codegen.library_path(f) != default
    monkeypatch.delenv("CC")
    monkeypatch.delenv("COMPOSE_CACHE_DIR")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert codegen.cache_dir() == tmp_path / "home" / ".cache" / "compose"
