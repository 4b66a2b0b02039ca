"""The scenario language: bundled scenarios, defaults, every field, error locations, the bad-input corpus."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import typing
from pathlib import Path

import numpy as np
import pytest
from pydantic import BaseModel

import scenarios.bundled as bundled
from scenarios import (BODY_PRESETS, HANDLE_NAMES, JOINT_DOF_NAMES, JOINT_NAMES, InputError, Scenario,
                       bundled_scenarios, bundled_styles, load_scenario, parse_scenario, scenario_json_schema)
from scenarios.schema import joint_dofs
from schedules.cli.main import main
from schedules.cli.scenario import check_scenario

HERE = Path(__file__).resolve().parents[1]
BAD = sorted((HERE / "bad_inputs").glob("*.yaml"))
FULL = HERE / "scenarios" / "full.yaml"
BUNDLED = list(bundled_scenarios())


# --- names shared with the character model ------------------------------------------------------

def test_names_agree_with_character_model():
    from scenegraph.model.body import JOINT_DOF_NAMES as SG_DOFS, PRESETS, make_character
    assert JOINT_DOF_NAMES == SG_DOFS
    assert set(BODY_PRESETS) == set(PRESETS)
    for preset in BODY_PRESETS:
        assert set(HANDLE_NAMES) == {h.name for h in make_character(preset).handles}
    assert sorted(d for j in JOINT_NAMES for d in joint_dofs(j)) == sorted(JOINT_DOF_NAMES)
    assert joint_dofs("knee_l") == ("knee_flex_l",)
    assert joint_dofs("waist") == ("waist_flex", "waist_lat", "waist_twist")
    assert joint_dofs("shoulder_flex_r") == ("shoulder_flex_r",)


# --- bundled scenarios --------------------------------------------------------------------------

def test_bundled_scenarios_present():
    assert {"walk", "walk_to", "two_walkers", "walk_to_run", "handhold", "tackle", "tackle_dodge", "two_tacklers",
            "suitcase", "limp", "uphill", "downhill", "turn180", "springy_run"} <= set(BUNDLED)
    assert "default" in bundled_styles()


@pytest.mark.parametrize("name", BUNDLED)
def test_bundled_scenario_validates(name):
    scn = load_scenario(name)
    check_scenario(scn)
    assert scn.name == name
    assert scn.description, "bundled scenarios need a one-line description for `compose list`"
    if scn.is_edit:  # an edit of a captured clip: no characters, no duration (tests/language/test_edit_block.py)
        assert scn.edit.clip.startswith("clips/") and not scn.characters
        return
    assert 1.0 <= scn.duration <= 2.0, "keep bundled scenarios short so they run end to end quickly"
    for c in scn.characters:
        assert c.style in bundled_styles(), f"{name}: style {c.style!r} is not shipped"


def test_bundled_name_and_path_resolve_alike():
    a = load_scenario("tackle")
    b = load_scenario(str(bundled_scenarios()["tackle"]))
    assert a == b


def test_unknown_bundled_name_suggests():
    with pytest.raises(InputError) as e:
        load_scenario("tackel")
    assert "did you mean 'tackle'" in str(e.value)


# --- minimal and full scenarios -----------------------------------------------------------------

def test_numbers_read_as_a_person_writes_them():
    """YAML 1.2 scalars: 1e0-style exponents are numbers (PyYAML's YAML 1.1 makes 1e6 and
    1.0e300 strings); a quoted number stays a string and is refused as one."""
    from scenarios.yamlio import parse_yaml
    data, _ = parse_yaml("a: 1e6\nb: 1.0e300\nc: '1e6'\nd: -2.5E-3\ne: 1e\nf: 15e-1\n")
    assert data == {"a": 1e6, "b": 1e300, "c": "1e6", "d": -2.5e-3, "e": "1e", "f": 1.5}
    scn = parse_scenario("name: m\nduration: 12e-1\ncharacters:\n  - name: a\n", "m.yaml")
    assert scn.duration == 1.2
    with pytest.raises(InputError, match="m.yaml:2:11 duration"):
        parse_scenario("name: m\nduration: '12e-1'\ncharacters:\n  - name: a\n", "m.yaml")


def test_plausible_walk_to_and_reach_are_accepted():
    """The plausibility limits leave room for real motions: 10 m in 1 s (a sprint), a palm
    at floor height, a reach target on a slope above its plane."""
    text = """name: ok
duration: 2.0
environment:
  slopes:
    - angle: 10
      region: {min: [2.0, -1.0], max: [6.0, 1.0]}
characters:
  - name: a
goals:
  - {type: walk_to, character: a, target: [10.0, 0.0], time: 1.0}
  - {type: walk_to, character: a, target: [10.0, 5.0], time: 2.0, waypoints: [[12.0, 2.0]]}
  - {type: reach, character: a, handle: palm_r, target: [4.0, 0.0, 0.0], time: 0.5}
  - {type: reach, character: a, handle: palm_l, target: [5.0, 0.0, 0.2], time: 0.6}
"""
    scn = parse_scenario(text, "ok.yaml")
    assert scn.ground_height(5.0, 0.0) == pytest.approx(np.tan(np.radians(10)) * 1.0)
    with pytest.raises(InputError, match=r"ok.yaml:\d+:\d+ goals\[3\].target: .*below the ground"):
        parse_scenario(text.replace("[5.0, 0.0, 0.2]", "[5.0, 0.0, 0.1]"), "ok.yaml")


def test_minimal_scenario_defaults():
    scn = parse_scenario("name: m\nduration: 1.0\ncharacters:\n  - name: a\n", "m.yaml")
    c = scn.characters[0]
    assert c.body.preset == "adult_male" and c.body.height is None and c.body.mass is None
    assert c.style == "default" and c.start.position == (0.0, 0.0) and c.start.heading == 0.0
    assert c.body.shoe_stiffness_scale == 1.0 and not c.body.extra_masses
    assert scn.timing == "fixed" and scn.goals == [] and scn.couplings == [] and scn.schedule is None
    # the default μ is the model's (scenegraph.model.dynamics.MU, what the solver always used on flat ground)
    from scenegraph.model.dynamics import MU
    assert scn.environment.ground.friction == MU and scn.environment.slopes == []
    assert scn.style_file("default") is None


def _model_classes(tp, out: set):
    if isinstance(tp, type) and issubclass(tp, BaseModel):
        if tp in out:
            return
        out.add(tp)
        for f in tp.model_fields.values():
            _model_classes(f.annotation, out)
        return
    for arg in typing.get_args(tp):
        _model_classes(arg, out)


def _used_fields(value, out: set):
    if isinstance(value, BaseModel):
        for f in value.model_fields_set:
            out.add((type(value).__name__, f))
            _used_fields(getattr(value, f), out)
    elif isinstance(value, (list, tuple)):
        for v in value:
            _used_fields(v, out)
    elif isinstance(value, dict):
        for v in value.values():
            _used_fields(v, out)


def test_full_scenario_uses_every_field():
    scn = load_scenario(FULL)
    check_scenario(scn)
    classes: set = set()
    _model_classes(Scenario, classes)
    every = {(c.__name__, f) for c in classes for f in c.model_fields}
    used: set = set()
    _used_fields(scn, used)
    edit = load_scenario(FULL.parent / "full_edit.yaml")  # an edit scenario's fields exclude the others'
    _used_fields(edit, used)
    assert not sorted(every - used), f"tests/scenarios/full.yaml and full_edit.yaml do not use {sorted(every - used)}"
    # style paths resolve against the scenario's folder, not the working directory
    assert scn.style_file("custom.style.yaml") == (FULL.parent / "custom.style.yaml").resolve()


def test_round_trip_through_model_dump():
    scn = load_scenario(FULL)
    again = Scenario.model_validate(scn.model_dump(), context={"base_dir": FULL.parent})
    assert again.model_dump() == scn.model_dump()


# --- error messages: file:line:col field: message -------------------------------------------------

BASE = "name: t\nduration: 2.0\ncharacters:\n  - name: alice\n  - name: bob\n"
ERRORS = [
    # (yaml, expected prefix "line:col field", message fragment)
    ("name: t\nduration: -2\ncharacters:\n  - name: a\n", "2:11 duration", "greater than 0"),
    (BASE + "    style: dfault\n", "6:12 characters[1].style",
     "unknown style 'dfault' (known: default, "),
    (BASE + "goals:\n  - type: walk_to\n    character: carol\n    target: [1, 0]\n    time: 1\n",
     "8:16 goals[0].character", "unknown character 'carol' (known: alice, bob)"),
    (BASE + "goals:\n  - type: walk_to\n    character: bob\n    target: [1, 0]\n    time: 2.5\n",
     "10:11 goals[0].time", "time 2.5 s is outside the scenario [0, 2.0] s"),
    (BASE + "couplings:\n  - type: hand_hold\n    between:\n      - {character: alice, handle: palm_r}\n"
            "      - {character: bob, handle: plam_l}\n    interval: [0, 1]\n",
     "10:34 couplings[0].between[1].handle", "did you mean 'palm_l'?"),
    (BASE + "couplings:\n  - type: hand_hold\n    between:\n      - {character: alice, handle: palm_r}\n"
            "      - {character: bob, handle: palm_l}\n    interval: [1.0, 1.0]\n",
     "11:15 couplings[0].interval", "must be after its start"),
    (BASE + "goals:\n  - type: tackle\n    attacker: alice\n    target: bob\n    time: 1\n    velocity: 3\n",
     "11:15 goals[0].velocity", "unknown field 'velocity'"),
    (BASE + "goals:\n  - type: tackel\n", "7:11 goals[0].type", "unknown type 'tackel'"),
    ("name: t\nduration: 1\n", "1:1 characters", "missing required field 'characters'"),
    (BASE + "characters: []\n", "6:1 characters", "duplicate key 'characters'"),
]


@pytest.mark.parametrize("text,where,fragment", ERRORS)
def test_error_names_file_line_column_and_field(text, where, fragment, tmp_path):
    with pytest.raises(InputError) as e:
        parse_scenario(text, "t.yaml", base_dir=tmp_path)
    msg = str(e.value).splitlines()[0]
    assert msg.startswith(f"t.yaml:{where}: "), msg
    assert fragment in msg, msg
    assert e.value.exit_code == 2


def test_unknown_style_suggests_close_bundled_name(monkeypatch, tmp_path):
    styles = tmp_path / "styles"
    styles.mkdir()
    for n in ("walk", "run", "walk2"):
        (styles / f"{n}.yaml").write_text("name: x\n")
    monkeypatch.setattr(bundled, "STYLES_DIR", styles)
    assert list(bundled_styles()) == ["default", "run", "walk", "walk2"]
    with pytest.raises(InputError) as e:
        parse_scenario(BASE + "    style: rnu\n", "tackle.yaml", base_dir=tmp_path)
    assert str(e.value).startswith("tackle.yaml:6:12 characters[1].style: unknown style 'rnu' "
                                   "(known: default, run, walk, walk2); did you mean 'run'?")


def test_cross_field_errors_are_all_listed(tmp_path):
    text = BASE + ("goals:\n  - type: walk_to\n    character: carol\n    target: [1, 0]\n    time: 5\n")
    with pytest.raises(InputError) as e:
        parse_scenario(text, "t.yaml", base_dir=tmp_path)
    assert str(e.value).splitlines()[0].startswith("t.yaml:8:16 goals[0].character")
    assert any(d.startswith("t.yaml:10:11 goals[0].time") for d in e.value.details)


# --- style paths ----------------------------------------------------------------------------------

def _write_style(path: Path):
    from scenegraph.model.style import default_style, save_style
    save_style(default_style(), path)


def test_style_path_relative_to_scenario_file(tmp_path, monkeypatch):
    sub = tmp_path / "shots"
    sub.mkdir()
    _write_style(sub / "mine.yaml")
    (sub / "s.yaml").write_text(BASE + "    style: mine.yaml\n")
    monkeypatch.chdir(tmp_path)  # the working directory must not matter
    scn = load_scenario(sub / "s.yaml")
    check_scenario(scn)
    assert scn.style_file("mine.yaml") == (sub / "mine.yaml").resolve()


def test_style_path_into_bundled_styles_is_allowed(tmp_path, monkeypatch):
    styles = tmp_path / "bundled_styles"
    styles.mkdir()
    _write_style(styles / "walk.yaml")
    monkeypatch.setattr(bundled, "STYLES_DIR", styles)
    (tmp_path / "shots").mkdir()
    (tmp_path / "shots" / "s.yaml").write_text(BASE + f"    style: {styles / 'walk.yaml'}\n")
    load_scenario(tmp_path / "shots" / "s.yaml")


def test_style_symlink_escaping_is_rejected(tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    _write_style(outside / "secret.yaml")
    shot = tmp_path / "shot"
    shot.mkdir()
    os.symlink(outside / "secret.yaml", shot / "link.yaml")
    (shot / "s.yaml").write_text(BASE + "    style: link.yaml\n")
    with pytest.raises(InputError) as e:
        load_scenario(shot / "s.yaml")
    assert "leaves the allowed folders" in str(e.value)


def test_invalid_style_file_is_reported_at_the_scenario_field(tmp_path, capsys):
    (tmp_path / "broken.yaml").write_text("name: broken\nalpha: 3\n")
    (tmp_path / "s.yaml").write_text(BASE + "    style: broken.yaml\n")
    assert main(["validate", str(tmp_path / "s.yaml")]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 's.yaml'}:6:12 characters[1].style: style 'broken.yaml' is invalid" in err
    assert "broken.yaml" in err


# --- the bad-input corpus through the CLI -----------------------------------------------------------

EXPECT = re.compile(r"^# expect: (\d+) (\S+)")


def _expectation(path: Path) -> tuple[int, str]:
    m = EXPECT.match(path.read_text(encoding="utf-8").splitlines()[0])
    assert m, f"{path.name}: first line must be '# expect: LINE FIELD'"
    return int(m.group(1)), m.group(2)


def test_bad_input_corpus_is_large_enough():
    assert len(BAD) >= 25


def _snapshot(folder: Path) -> dict:
    return {p: p.stat().st_mtime_ns for p in folder.rglob("*")}


@pytest.mark.parametrize("path", BAD, ids=[p.stem for p in BAD])
def test_bad_input_rejected_with_line_and_field(path, tmp_path, monkeypatch, capsys):
    line, field = _expectation(path)
    monkeypatch.chdir(tmp_path)
    before = _snapshot(path.parent)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()[0]
    assert err.startswith(f"compose: error: {path}:{line}:"), err
    if field != "-":
        assert re.match(rf"compose: error: {re.escape(str(path))}:{line}:\d+ {re.escape(field)}: ", err), err
    else:
        assert re.match(rf"compose: error: {re.escape(str(path))}:{line}:\d+: ", err), err
    # nothing written: not by validate, not by schedule --dot
    assert main(["schedule", str(path), "--dot", str(tmp_path / "out.dot")]) == 2
    assert list(tmp_path.iterdir()) == []
    assert _snapshot(path.parent) == before


def test_validate_reports_every_file_and_exit_code_through_console_script(tmp_path):
    good = bundled_scenarios()["walk"]
    bad = [p for p in BAD if p.stem in ("unknown_style", "duration_negative")]
    res = subprocess.run([sys.executable, "-m", "schedules.cli.main", "validate", str(good), *map(str, bad)],
                         capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert res.returncode == 2
    assert "ok: " in res.stdout
    assert all(str(p) in res.stderr for p in bad)
    assert list(tmp_path.iterdir()) == []


# --- schema, list ---------------------------------------------------------------------------------------

def test_schema_command_prints_json_schema(capsys):
    assert main(["schema"]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["title"] == "compose scenario"
    assert {"characters", "goals", "couplings", "schedule", "duration"} <= set(schema["properties"])
    assert "seconds" in json.dumps(schema) or "(s)" in json.dumps(schema)


def test_bundled_scenarios_satisfy_json_schema():
    jsonschema = pytest.importorskip("jsonschema")
    from scenarios.yamlio import load_yaml
    schema = scenario_json_schema()
    for path in [*bundled_scenarios().values(), FULL]:
        data, _ = load_yaml(path)
        jsonschema.validate(data, schema)


def test_list_command(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for name in BUNDLED:
        assert re.search(rf"^  {name}\s+\S", out, re.M), name
    assert re.search(r"^  default\s+built-in", out, re.M)


def test_gait_change_generates_walk_then_run_footsteps():
    """`style_change` with `gait: run`: double support before the change, flight phases and
    quicker, longer steps after it; the footsteps still reach the walk_to target."""
    from scenarios.loader import load_scenario
    from scenegraph.world.scene import build_scene

    scene = build_scene(load_scenario("walk_to_run"))
    steps = sorted(scene.characters[0].footsteps, key=lambda f: f.t0)
    early = [f for f in steps if f.t1 < 0.9]
    late = [f for f in steps if f.t0 > 1.2]
    assert early and late
    assert all(f.heel is not None for f in early) and all(f.heel is None for f in late)
    gaps = [b.t0 - a.t1 for a, b in zip(steps, steps[1:])]
    assert any(g < 0 for g, a in zip(gaps, steps) if a.t1 < 0.9)  # double support while walking
    assert all(g > 0.02 for g, a in zip(gaps, steps) if a.t0 > 1.2)  # flight while running
    lengths = [b.position[0] - a.position[0] for a, b in zip(steps, steps[1:])]
    assert lengths[-1] > 1.4 * lengths[0]
    assert 4.4 - 1.2 < steps[-1].position[0] < 4.4  # the last landing is one run step short of the end


def test_initial_motion_from_the_styles_example(tmp_path):
    """`initial_motion: example` takes the initial guess's joint angles from the poses the
    learned style carries (matched by leg phase, paper §7); the generator's differ.  A style
    without example poses is an input error at that field's line."""
    from scenegraph.model.body import N_ROOT
    from scenegraph.model.gait import leg_phase, phase_code
    from scenegraph.world.scene import build_scene
    from scenegraph.model.style import load_style

    text = (bundled.BUNDLED_DIR / "walk.yaml").read_text()
    assert "    style: walk\n" in text
    ex_file = tmp_path / "walk_ex.yaml"
    ex_file.write_text(text.replace("    style: walk\n", "    style: walk\n    initial_motion: example\n"))
    ex, gen = (build_scene(load_scenario(f)).characters[0] for f in (ex_file, bundled.BUNDLED_DIR / "walk.yaml"))
    codes, joints = load_style(bundled.STYLES_DIR / "walk.yaml").example.arrays()
    t = 0.4
    code = np.array([phase_code(leg_phase(ex.footsteps, f, t)) for f in ("l", "r")])
    d = np.abs(codes - code)
    j = int(np.argmin(np.minimum(d, 2 - d).sum(axis=1)))
    q_ex, q_gen = (np.asarray(c.motion.at([t])[0]).ravel()[N_ROOT:] for c in (ex, gen))
    assert np.degrees(np.sqrt(np.mean((q_ex - joints[j]) ** 2))) < 5.0  # spline fit of the sampled poses
    assert np.degrees(np.sqrt(np.mean((q_gen - joints[j]) ** 2))) > 2 * np.degrees(
        np.sqrt(np.mean((q_ex - joints[j]) ** 2)))
    bad = tmp_path / "walk_default.yaml"
    bad.write_text(ex_file.read_text().replace("    style: walk\n", "    style: default\n"))
    with pytest.raises(InputError) as exc:
        build_scene(load_scenario(bad))
    line = bad.read_text().splitlines().index("    initial_motion: example") + 1
    assert f"{bad}:{line}:" in str(exc.value) and "no example poses" in str(exc.value)
