"""`compose preview`, `export-bvh` and `learn` given a wrong, truncated, empty, binary or
foreign file: one clear line on stderr, exit code 2, nothing written (the bad files are in
tests/bad_inputs/)."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from schedules.cli.main import main

BAD = Path(__file__).resolve().parents[1] / "bad_inputs"
GOLDEN = Path(__file__).resolve().parents[1] / "golden" / "two_characters.usda"

STAGES = {  # file → fragment of the error
    "png_renamed.usda": "not a readable USD stage",
    "empty.usda": "is empty, not a USD stage",
    "not_compose.usda": "has no UsdSkel character",
    "truncated_stage.usda": "not a readable USD stage",
}
CLIPS = {
    "png_renamed.bvh": "file is a PNG image, not a BVH file",
    "empty.bvh": "empty file",
    "truncated_motion.bvh": "truncated motion",
    "not_compose.usda": "expected 'HIERARCHY'",
}


def _run(argv, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    return code, [ln for ln in err if not ln.startswith("compose learn:")]  # learn's progress header


def _copy(name, tmp_path) -> Path:
    inp = tmp_path / "in"
    inp.mkdir(exist_ok=True)
    return Path(shutil.copy(BAD / name, inp / name))


@pytest.mark.parametrize("name", sorted(STAGES))
@pytest.mark.parametrize("command", ["preview", "export-bvh"])
def test_bad_stage(command, name, tmp_path, monkeypatch, capsys):
    f = _copy(name, tmp_path)
    out = tmp_path / ("out.png" if command == "preview" else "out.bvh")
    code, err = _run([command, str(f), "-o", str(out)], tmp_path, monkeypatch, capsys)
    assert code == 2
    assert len(err) == 1 and err[0].startswith("compose: error: ") and STAGES[name] in err[0], err
    assert "Traceback" not in err[0] and "pxrInternal" not in err[0]
    assert sorted(p.name for p in tmp_path.rglob("*")) == sorted(["in", name])  # nothing written


@pytest.mark.parametrize("name", sorted(CLIPS))
def test_bad_clip_for_learn(name, tmp_path, monkeypatch, capsys):
    f = _copy(name, tmp_path)
    code, err = _run(["learn", str(f), "--frames", "1:60", "-o", str(tmp_path / "style.yaml")],
                     tmp_path, monkeypatch, capsys)
    assert code == 2
    assert len(err) == 1 and err[0].startswith(f"compose: error: {f}:") and CLIPS[name] in err[0], err
    assert sorted(p.name for p in tmp_path.rglob("*")) == sorted(["in", name])


@pytest.mark.parametrize("argv, fragment", [
    (["-o", "{tmp}/missing/style.yaml"], "does not exist"),
    (["-o", "{tmp}/style.txt"], "expected a file ending in .yaml"),
    (["-o", "{tmp}"], "is a directory"),
    (["-o", "{tmp}/s.yaml", "--max-iter", "0"], "--max-iter 0"),
])
def test_learn_checks_its_arguments_before_reading_the_clip(argv, fragment, tmp_path, monkeypatch, capsys):
    f = _copy("truncated_motion.bvh", tmp_path)  # a bad clip: the argument error must come first
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code, err = _run(["learn", str(f), "--frames", "1:60", *argv], tmp_path, monkeypatch, capsys)
    assert code == 2 and len(err) == 1 and fragment in err[0], err
    assert sorted(p.name for p in tmp_path.rglob("*")) == sorted(["in", "truncated_motion.bvh"])


@pytest.mark.parametrize("command, argv, fragment", [
    ("export-bvh", ["-o", "{tmp}/nowhere/x.bvh"], "does not exist"),
    ("export-bvh", ["-o", "{tmp}/x.usda"], "expected a file ending in .bvh"),
    ("export-bvh", ["--fps", "0"], "--fps 0"),
    ("export-bvh", ["--fps", "nan"], "--fps nan"),
    ("preview", ["-o", "{tmp}/x.txt"], "expected a file ending in"),
    ("preview", ["--frames", "0"], "--frames 0"),
    ("preview", ["--frames", "100000"], "--frames 100000"),
])
def test_stage_commands_check_arguments(command, argv, fragment, tmp_path, monkeypatch, capsys):
    inp = tmp_path / "in"
    inp.mkdir()
    stage = Path(shutil.copy(GOLDEN, inp / GOLDEN.name))
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code, err = _run([command, str(stage), *argv], tmp_path, monkeypatch, capsys)
    assert code == 2 and len(err) == 1 and fragment in err[0], err
    assert sorted(p.name for p in tmp_path.rglob("*")) == sorted(["in", GOLDEN.name])


def test_console_script_prints_no_traceback(tmp_path):
    """Through a real process: the USD library's own error text becomes one line, exit 2."""
    f = _copy("png_renamed.usda", tmp_path)
    res = subprocess.run([sys.executable, "-m", "schedules.cli.main", "export-bvh", str(f)], capture_output=True,
                         text=True, cwd=tmp_path, timeout=300)
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "not a readable USD stage" in lines[0] and "Traceback" not in res.stderr, res.stderr
    assert sorted(p.name for p in tmp_path.rglob("*")) == sorted(["in", "png_renamed.usda"])


@pytest.mark.parametrize("edit, fragment", [
    (("endTimeCode = 2", "endTimeCode = 1e12"), "above the limit of 1000000"),
    (("timeCodesPerSecond = 10", "timeCodesPerSecond = -5"), "is not a frame rate"),
    (("startTimeCode = 0", "startTimeCode = 50"), "is not a valid animation range"),
])
@pytest.mark.parametrize("command", ["preview", "export-bvh"])
def test_stage_with_a_broken_time_range(command, edit, fragment, tmp_path, monkeypatch, capsys):
    """A stage header asking for 10¹² frames, a negative frame rate or a reversed range is
    refused before any joint transform is read."""
    inp = tmp_path / "in"
    inp.mkdir()
    text = GOLDEN.read_text()
    assert edit[0] in text
    stage = inp / "edited.usda"
    stage.write_text(text.replace(edit[0], edit[1], 1))
    code, err = _run([command, str(stage), "-o", str(tmp_path / ("o.png" if command == "preview" else "o.bvh"))],
                     tmp_path, monkeypatch, capsys)
    assert code == 2 and len(err) == 1 and fragment in err[0], err
    assert sorted(p.name for p in tmp_path.rglob("*")) == sorted(["in", "edited.usda"])
