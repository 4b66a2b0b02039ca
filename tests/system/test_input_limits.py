"""Resource limits on inputs (docs/reliability.md, "Input limits"): each is checked before
anything large is allocated and is reported as a located error (file:line[:col])."""
from __future__ import annotations

import dataclasses
import time
import tracemalloc
from pathlib import Path

import pytest

from scenarios import schema
from scenarios.errors import InputError
from scenarios.loader import MAX_SCENARIO_BYTES, load_scenario, parse_scenario
from scenarios.yamlio import MAX_DEPTH, MAX_NODES, parse_yaml, read_text
from scenegraph.mocap import bvh as bvh_mod
from scenegraph.mocap.bvh import parse_bvh, read_bvh
from scenegraph.mocap.clip import read_clip

CLIP = Path(__file__).resolve().parents[2] / "scenarios" / "clips" / "walk_neutral_cmu_07_01.bvh"
MINIMAL = "name: m\nduration: 1.2\ncharacters:\n  - name: a\n"


def _peak_mb(fn) -> tuple[float, BaseException | None]:
    """Peak Python allocation (MB) while ``fn`` runs, and what it raised."""
    tracemalloc.start()
    err = None
    try:
        fn()
    except InputError as exc:
        err = exc
    finally:
        peak = tracemalloc.get_traced_memory()[1] / 1e6
        tracemalloc.stop()
    return peak, err


# --- constants the language layer keeps in step with the world model ---------------------------

def test_limits_agree_with_the_character_model_and_solver():
    from scenegraph.model.body import PRESETS
    from scenegraph.mocap.clip import MAX_STATURE, MIN_STATURE
    from scenegraph.problem.subproblem import Subproblem

    assert schema.PRESET_HEIGHTS == {k: p.height for k, p in PRESETS.items()}
    fields = {f.name: f.default for f in dataclasses.fields(Subproblem)}
    assert schema.COLLOCATION_HZ == fields["collocation_hz"]
    bh = schema.BodySpec.model_fields["height"].metadata
    assert (MIN_STATURE, MAX_STATURE) == (next(m.ge for m in bh if hasattr(m, "ge")),
                                          next(m.le for m in bh if hasattr(m, "le")))


# --- scenario text -------------------------------------------------------------------------------

def test_scenario_file_size_is_refused_before_reading(tmp_path):
    f = tmp_path / "big.yaml"
    f.write_text(MINIMAL + ("# padding\n" * (MAX_SCENARIO_BYTES // 10 + 10)))
    peak, err = _peak_mb(lambda: load_scenario(str(f)))
    assert err is not None and "larger than the 256000 bytes a scenario file may have" in str(err)
    over = MAX_SCENARIO_BYTES - len(MINIMAL)  # the first byte beyond the limit, in the padding
    assert err.location.file == str(f)
    assert (err.location.line, err.location.column) == (MINIMAL.count("\n") + over // 10 + 1, over % 10 + 1)
    assert peak < 1.0  # nothing of the file was read


def test_size_limit_of_a_huge_sparse_file_costs_nothing(tmp_path):
    f = tmp_path / "huge.bvh"
    with open(f, "wb") as fh:
        fh.truncate(bvh_mod.MAX_BYTES + 1)  # 100 MB of zeros, no disk used
    t = time.perf_counter()
    peak, err = _peak_mb(lambda: read_bvh(f))
    assert err is not None and "larger than the 100000000 bytes" in str(err)
    assert err.location.line == 1 and err.location.column == bvh_mod.MAX_BYTES + 1
    assert peak < 5.0 and time.perf_counter() - t < 30


def test_yaml_nesting_limit_without_recursion():
    for depth in (MAX_DEPTH + 1, 100_000):
        text = "a: " + "[" * depth + "]" * depth + "\n"
        with pytest.raises(InputError, match=f"nesting deeper than {MAX_DEPTH}") as ei:
            parse_yaml(text, "deep.yaml")
        assert ei.value.location.line == 1
    parse_yaml("a: " + "[" * (MAX_DEPTH - 1) + "]" * (MAX_DEPTH - 1) + "\n", "ok.yaml")  # the mapping is a level


def test_yaml_value_count_limit():
    text = "a: [" + ",".join(["0"] * (MAX_NODES + 1)) + "]\n"
    with pytest.raises(InputError, match=f"more than {MAX_NODES} values") as ei:
        parse_yaml(text, "many.yaml")
    assert ei.value.location.line == 1


def test_non_utf8_is_located_and_a_bom_is_accepted(tmp_path):
    f = tmp_path / "latin1.yaml"
    f.write_bytes(MINIMAL.encode() + b"description: caf\xe9\n")
    with pytest.raises(InputError, match="not UTF-8") as ei:
        read_text(f, "scenario", 10_000)
    assert (ei.value.location.line, ei.value.location.column) == (5, 17)
    g = tmp_path / "bom.yaml"
    g.write_bytes(b"\xef\xbb\xbf" + MINIMAL.encode())
    assert load_scenario(str(g)).name == "m"


def test_character_seconds_limit():
    text = MINIMAL.replace("duration: 1.2", "duration: 30") + "  - name: b\n    start: {position: [0, 2]}\n"
    parse_scenario(text, "ok.yaml")  # 2 × 30 s = 60: at the limit
    with pytest.raises(InputError, match=r"bad.yaml:2:\d+ duration: 2 character\(s\) × 31 s = 62"):
        parse_scenario(text.replace("duration: 30", "duration: 31"), "bad.yaml")


def _footprints(n: int, t_start: float = 0.0) -> str:
    rows = []
    for i in range(n):
        t0 = t_start + i * 0.05
        rows.append(f"      - {{foot: {'lr'[i % 2]}, position: [{0.05 * i:.2f}, {0.1 if i % 2 == 0 else -0.1}], "
                    f"time: [{t0:.2f}, {t0 + 0.05:.2f}]}}")
    return "\n".join(rows)


def test_footprint_count_limit():
    head = "name: f\nduration: 60\ncharacters:\n  - name: a\ngoals:\n"
    goal = "  - type: footprints\n    character: a\n    steps:\n"
    ok = head + goal + _footprints(1000)
    assert len(parse_scenario(ok, "ok.yaml").goals[0].steps) == schema.MAX_FOOTPRINTS
    bad = head + goal + _footprints(600) + "\n" + goal + _footprints(401, 30.0)
    with pytest.raises(InputError, match=r"bad.yaml:\d+:\d+ goals\[1\].steps: more than 1000 footprints") as ei:
        parse_scenario(bad, "bad.yaml")
    assert ei.value.location.line == 5 + 3 + 600 + 3 + 1  # the second goal's steps


def test_goal_count_limit():
    goals = "".join(f"  - {{type: reach, character: a, handle: palm_r, target: [0.3, 0, 1], time: {i * 0.001:.3f}}}\n"
                    for i in range(schema.MAX_GOALS + 1))
    with pytest.raises(InputError, match=r"bad.yaml:6:\d+ goals: .*at most 200"):
        parse_scenario(MINIMAL + "goals:\n" + goals, "bad.yaml")


# --- BVH -----------------------------------------------------------------------------------------

def _clip_text() -> str:
    return CLIP.read_text()


def test_bvh_frame_count_is_checked_before_allocating():
    head, _, motion = _clip_text().partition("MOTION")
    lines = motion.strip("\n").splitlines()
    for frames, msg in ((10 ** 12, "above the limit of 1000000"), (900_000, "truncated motion")):
        text = f"{head}MOTION\nFrames: {frames}\n{lines[1]}\n" + "\n".join(lines[2:5]) + "\n"
        peak, err = _peak_mb(lambda: parse_bvh(text, "x.bvh"))
        assert err is not None and msg in str(err), err
        assert peak < 20  # 900 000 × 62 channels would be 446 MB
    frames_line = head.count("\n") + 2
    assert err is not None and f"(line {frames_line})" in str(err)


def test_bvh_deep_and_wide_hierarchies():
    deep = "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
    deep += "".join(f"JOINT j{k}\n{{\nOFFSET 0 1 0\nCHANNELS 1 Zrotation\n" for k in range(5000))
    deep += "}\n" * 5001 + "MOTION\nFrames: 1\nFrame Time: 0.01\n0 0 0\n"
    with pytest.raises(InputError, match=f"nested deeper than {bvh_mod.MAX_DEPTH}") as ei:
        parse_bvh(deep, "deep.bvh")
    assert ei.value.location.line == 6 + 4 * bvh_mod.MAX_DEPTH - 4  # the JOINT at depth MAX_DEPTH + 1
    wide = "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 0\n"
    wide += "".join(f"JOINT w{k}\n{{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
                    f"Yrotation\n}}\n" for k in range(200))
    with pytest.raises(InputError, match=f"more than {bvh_mod.MAX_CHANNELS} channels"):
        parse_bvh(wide + "}\nMOTION\n", "wide.bvh")
    many = "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 0\n" + "".join(
        f"JOINT w{k}\n{{\nOFFSET 0 0 0\nCHANNELS 0\n}}\n" for k in range(bvh_mod.MAX_JOINTS + 5))
    with pytest.raises(InputError, match=f"more than {bvh_mod.MAX_JOINTS} joints"):
        parse_bvh(many + "}\nMOTION\n", "many.bvh")


def test_bvh_values_beyond_the_limit_are_located():
    text = _clip_text()
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("Frame Time")) + 3  # a motion line
    toks = lines[k].split()
    toks[4] = "1e300"
    lines[k] = " ".join(toks)
    with pytest.raises(InputError, match="beyond") as ei:
        parse_bvh("\n".join(lines) + "\n", "v.bvh")
    assert ei.value.location.line == k + 1 and ei.value.location.column == len(" ".join(toks[:4])) + 2


def test_clip_with_an_implausible_stature_is_refused(tmp_path):
    import re

    def scale(m):  # every OFFSET × 100: a 170 m performer in the rig's unit
        return "OFFSET " + " ".join(f"{float(v) * 100:g}" for v in m.group(1).split())

    f = tmp_path / "giant.bvh"
    f.write_text(re.sub(r"OFFSET ([^\n]+)", scale, _clip_text()))
    with pytest.raises(InputError, match=r"stature of .* m, outside 0.5–2.5 m") as ei:
        read_clip(f, frames=(1, 40))
    assert ei.value.location.file == str(f) and ei.value.location.line == 2  # the ROOT
