"""The scenario ``edit:`` block (scenarios/edit_block.py, issue 20 item 3) and its run
(schedules/execution/edit_run.py): located errors, fields without effect rejected, and the
bundled ``edit_broad_jump`` end to end — the stage, the BVH and a report whose figures are
measured from what was written (the flight from the stage's meshes), beside the naive
displacement-map edit of the same clip.  Bad edit files are also in tests/bad_inputs.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from scenarios import InputError, load_scenario, parse_scenario, scenario_json_schema
from scenarios.bundled import BUNDLED_DIR
from scenarios.edit_block import EDIT_EXCLUDES
from schedules.cli.main import main

CLIPS = BUNDLED_DIR / "clips"
HEAD = f"name: e\nedit:\n  clip: {CLIPS / 'jump_broad_cmu_16_05.bvh'}\n  further_m: 0.3\n"
SYNTH = {"characters": "characters:\n  - name: a\n", "goals": "goals: []\n", "couplings": "couplings: []\n",
         "schedule": "schedule: {kind: auto}\n", "duration": "duration: 1.0\n", "timing": "timing: fixed\n",
         "duration_bounds": "duration_bounds: [1, 2]\n", "environment": "environment: {}\n"}


def test_the_bundled_edit_scenario_loads():
    scn = load_scenario("edit_broad_jump")
    assert scn.is_edit and not scn.characters and scn.duration is None
    e = scn.edit
    assert (e.clip, e.frames, e.further_m, e.higher_m, e.turn_deg, e.character) == (
        "clips/jump_broad_cmu_16_05.bvh", (60, 250), 0.3, 0.0, 0.0, "jumper")
    assert (CLIPS / "jump_broad_cmu_16_05.bvh").is_file()
    # shipped with CMU's acknowledgement (scenarios/clips/README.md)
    readme = (CLIPS / "README.md").read_text()
    assert "mocap.cs.cmu.edu" in readme and "jump_broad_cmu_16_05.bvh" in readme


@pytest.mark.parametrize("field", EDIT_EXCLUDES)
def test_a_synthesis_field_in_an_edit_scenario_is_rejected_where_it_is(field):
    assert set(SYNTH) == set(EDIT_EXCLUDES)
    with pytest.raises(InputError) as e:
        parse_scenario(HEAD + SYNTH[field], "e.yaml")
    assert re.match(rf"e.yaml:[56]:\d+ {field}: ", str(e.value)), str(e.value)
    assert "has no effect" in str(e.value)


@pytest.mark.parametrize("line,field,where", [
    ("  turn_deg: 400\n", "turn_deg", "edit.turn_deg"),
    ("  further_m: '0.3'\n", "further_m", "edit.further_m"),
    ("  frames: [100, 101]\n", "frames", "edit.frames"),
    ("  frames: [-1, 100]\n", "frames", "edit.frames"),
    ("  character: 'two words'\n", "character", "edit.character"),
    ("  clip: jump.txt\n", "clip", "edit.clip"),
])
def test_bad_edit_fields_are_located(line, field, where):
    text = HEAD.replace("  further_m: 0.3\n", "") if field == "further_m" else HEAD
    if field == "clip":
        text = text.replace(f"  clip: {CLIPS / 'jump_broad_cmu_16_05.bvh'}\n", "")
    with pytest.raises(InputError) as e:
        parse_scenario(text + line, "e.yaml", base_dir=CLIPS)
    n = (text + line).count("\n")  # the bad line is the last one
    assert re.match(rf"e.yaml:{n}:\d+ {re.escape(where)}[\[:]", str(e.value)), str(e.value)


def test_a_synthesis_still_needs_its_duration_and_characters():
    with pytest.raises(InputError, match=r"t.yaml:1:1 duration: missing required field 'duration'"):
        parse_scenario("name: t\ncharacters:\n  - name: a\n", "t.yaml")
    with pytest.raises(InputError, match=r"t.yaml:1:1 characters: missing required field 'characters'"):
        parse_scenario("name: t\nduration: 1\n", "t.yaml")


def test_json_schema_tells_an_edit_from_a_synthesis():
    jsonschema = pytest.importorskip("jsonschema")
    schema = scenario_json_schema()
    jsonschema.validate({"name": "e", "edit": {"clip": "a.bvh", "further_m": 0.3}}, schema)
    jsonschema.validate({"name": "w", "duration": 1.0, "characters": [{"name": "a"}]}, schema)
    for bad in ({"name": "e", "duration": 1.0, "edit": {"clip": "a.bvh"}},  # edit with a synthesis field
                {"name": "w", "characters": [{"name": "a"}]}):  # a synthesis without its duration
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, schema)


def test_an_edit_validates_and_has_no_schedule(capsys):
    assert main(["validate", "edit_broad_jump"]) == 0
    assert "an edit of clips/jump_broad_cmu_16_05.bvh" in capsys.readouterr().out
    assert main(["schedule", "edit_broad_jump"]) == 2
    assert re.search(r"edit_broad_jump.yaml:(9|10):\d+ edit: an edit scenario has no schedule", capsys.readouterr().err)


def test_compose_run_edit_broad_jump(tmp_path, capsys):
    """The bundled edit end to end (fits the clip: ~10 s, the edit itself ~1 s)."""
    rc = main(["run", "edit_broad_jump", "-o", str(tmp_path / "e.usda"), "--report", str(tmp_path / "r.json"),
               "--run-dir", str(tmp_path / "run"), "--fps", "120"])
    err = capsys.readouterr().err
    assert rc == 0, err
    for f in ("e.usda", "e.bvh", "e_naive.usdc", "r.json"):
        assert (tmp_path / f).is_file(), f
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["passes"] and all(g["holds"] for g in rep["goals"].values()), rep["goals"]
    assert rep["goals"]["further_m"]["measured"] == pytest.approx(0.3, abs=0.02)
    assert abs(rep["goals"]["higher_m"]["measured"]) < 0.02 and abs(rep["goals"]["turn_deg"]["measured"]) < 2.0
    assert rep["momentum_corr"] >= 0.9
    # the flight measured from the written stage: a parabola, where the naive edit's is not
    assert rep["parabola_rms_mm"] <= 2.0 < rep["naive_parabola_rms_mm"]
    assert rep["edit_seconds"] < 20.0  # issue 20's goal for the edit
    assert err.strip().splitlines()[-1].startswith("edit: further_m=0.3 higher_m=0 turn_deg=0 momentum_corr=")
    # the BVH carries the edited motion, frame for frame with the stage, at the capture rate
    from scenegraph.mocap.bvh import read_bvh
    from scenegraph.stage_audit import read_stage
    bvh = read_bvh(tmp_path / "e.bvh")
    assert bvh.fps == 120 and bvh.n_frames == len(read_stage(tmp_path / "e.usda").times)


@pytest.mark.slow
def test_a_variant_not_bundled_turns_rises_and_names_its_character(tmp_path):
    """Another distance, a higher apex, a turn, another name, the whole clip: each field acts."""
    text = (f"name: v\nedit:\n  clip: {CLIPS / 'jump_broad_cmu_16_05.bvh'}\n  further_m: -0.2\n  higher_m: 0.1\n"
            "  turn_deg: 30\n  character: hopper\n")
    (tmp_path / "v.yaml").write_text(text)
    rc = main(["run", str(tmp_path / "v.yaml"), "-o", str(tmp_path / "v.usda"), "--report", str(tmp_path / "r.json"),
               "--run-dir", str(tmp_path / "run")])
    rep = json.loads((tmp_path / "r.json").read_text())
    g = rep["goals"]
    assert g["further_m"]["measured"] == pytest.approx(-0.2, abs=0.02)
    assert g["higher_m"]["measured"] == pytest.approx(0.1, abs=0.02)
    assert g["turn_deg"]["measured"] == pytest.approx(30.0, abs=2.0)
    assert rep["parabola_rms_mm"] <= 2.0
    from scenegraph.stage_audit import read_stage
    assert read_stage(tmp_path / "v.usda").characters[0].name == "hopper"
    assert rc == (0 if rep["passes"] else 1)


@pytest.mark.slow
def test_a_sweep_over_an_edit_field(tmp_path):
    out = tmp_path / "sw"
    rc = main(["sweep", "edit_broad_jump", "--vary", "edit.further_m=0.1,0.4", "-o", str(out), "--no-contact-sheet"])
    rows = (out / "summary.csv").read_text().splitlines()
    assert len(rows) == 3 and "momentum_corr" in rows[0]
    got = [json.loads((out / f"v{i:03d}" / "report.json").read_text())["goals"]["further_m"]["measured"]
           for i in (0, 1)]
    assert got == [pytest.approx(0.1, abs=0.02), pytest.approx(0.4, abs=0.02)]
    assert rc in (0, 1)
