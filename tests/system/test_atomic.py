"""The contract of the one atomic writer (scenarios/atomic.py): the destination holds its old
content or all of the new one, the mode follows the umask, temporary files never stay
behind, errors are compose errors; and no other module of the package renames files."""
from __future__ import annotations

import ast
import os
import stat
from pathlib import Path

import pytest

from scenarios.atomic import WriteError, atomic_path, atomic_write, file_mode
from scenarios.errors import ComposeError, InputError

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture()
def umask():
    """Set the process umask for one test and restore it."""
    old = os.umask(0o022)
    yield os.umask
    os.umask(old)


def test_complete_content_at_the_final_path(tmp_path):
    data = bytes(range(256)) * 4096  # 1 MiB: more than one write buffer
    p = atomic_write(tmp_path / "a.bin", data)
    assert p == tmp_path / "a.bin" and p.read_bytes() == data
    atomic_write(p, "ünïcode\n")
    assert p.read_text(encoding="utf-8") == "ünïcode\n"
    assert os.listdir(tmp_path) == ["a.bin"]


@pytest.mark.parametrize("mask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_mode_follows_the_umask(tmp_path, umask, mask, mode):
    umask(mask)
    assert file_mode() == mode
    p = atomic_write(tmp_path / "f.txt", "x")
    assert stat.S_IMODE(p.stat().st_mode) == mode
    with atomic_path(tmp_path / "lib.so", mode=0o755) as tmp:
        tmp.write_bytes(b"\x7fELF")
    assert stat.S_IMODE((tmp_path / "lib.so").stat().st_mode) == 0o755


@pytest.mark.parametrize("exc", [RuntimeError("writer crashed"), KeyboardInterrupt()])
def test_failure_while_writing_keeps_the_old_file_and_no_temporary(tmp_path, exc):
    p = tmp_path / "keep.txt"
    p.write_text("OLD")
    with pytest.raises(type(exc)):
        with atomic_path(p) as tmp:
            tmp.write_text("half of the new")
            raise exc
    assert p.read_text() == "OLD" and os.listdir(tmp_path) == ["keep.txt"]


def test_failure_on_a_fresh_path_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError):
        with atomic_path(tmp_path / "fresh.png", suffix=".png") as tmp:
            assert tmp.suffix == ".png" and tmp.parent == tmp_path and tmp.name.startswith(".fresh.png.")
            raise RuntimeError("no")
    assert os.listdir(tmp_path) == []


def test_os_failure_is_a_write_error_and_cleans_up(tmp_path, monkeypatch):
    p = tmp_path / "out.json"
    p.write_text("OLD")

    def no_replace(a, b):
        raise PermissionError("read-only file system")
    monkeypatch.setattr(os, "replace", no_replace)
    with pytest.raises(WriteError, match=r"could not write .*out\.json: read-only") as info:
        atomic_write(p, "{}")
    monkeypatch.undo()
    assert isinstance(info.value, ComposeError) and isinstance(info.value, OSError)
    assert info.value.exit_code == 1
    assert p.read_text() == "OLD" and os.listdir(tmp_path) == ["out.json"]


def test_missing_folder_is_an_input_error_unless_asked_to_create_it(tmp_path):
    with pytest.raises(InputError, match="does not exist") as info:
        atomic_write(tmp_path / "no" / "such" / "x.txt", "x")
    assert info.value.exit_code == 2 and os.listdir(tmp_path) == []
    p = atomic_write(tmp_path / "new" / "dir" / "x.txt", "x", make_parents=True)
    assert p.read_text() == "x" and os.listdir(p.parent) == ["x.txt"]


def test_no_other_module_writes_renames_or_makes_temporary_files():
    """One writer: outside scenarios/atomic.py the package calls none of ``os.replace``,
    ``rename``, ``mkstemp``, ``NamedTemporaryFile``, ``mkdtemp``, ``write_text``,
    ``write_bytes``, nor ``open`` with a writing mode (AST walk over every module; the run
    lock's ``os.open`` is not a content file and is allowed)."""
    banned = {"rename", "mkstemp", "NamedTemporaryFile", "mkdtemp", "write_text", "write_bytes"}
    offenders = []
    for pkg in ("scenarios", "scenegraph", "schedules"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            if path == ROOT / "scenarios" / "atomic.py":
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if not isinstance(node, ast.Call):
                    continue
                if isinstance(node.func, ast.Name) and node.func.id == "open":
                    mode = node.args[1] if len(node.args) > 1 else next(
                        (k.value for k in node.keywords if k.arg == "mode"), None)
                    if isinstance(mode, ast.Constant) and set(str(mode.value)) & set("wax+"):
                        offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} open {mode.value!r}")
                    continue
                if not isinstance(node.func, ast.Attribute):
                    continue
                name = node.func.attr
                owner = node.func.value
                os_replace = name == "replace" and isinstance(owner, ast.Name) and owner.id == "os"
                if name in banned or os_replace:
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} {name}")
    assert offenders == []
