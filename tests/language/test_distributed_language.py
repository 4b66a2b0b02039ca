"""The language side of crowds and sweeps: the ``repeat`` construct and ``--vary`` expansion."""
from __future__ import annotations

import pytest
import yaml

from scenarios.errors import InputError
from scenarios.loader import load_scenario, parse_scenario
from schedules.cli import main as cli
from schedules.plan.sweep import build_variants, combinations, parse_path, parse_values, parse_vary

BASE = """name: rep
duration: 1.0
characters:
  - {name: lead, body: {preset: adult_male}, style: walk, start: {position: [0.0, 9.0], heading: 0}}
repeat:
  - for:
      i: [1, 2, 3]
      y: [-1.0, 0.5, 2.0]
    characters:
      - name: w${i}
        body: {preset: adult_male}
        style: walk
        start: {position: [0.0, "${y}"], heading: 0}
    goals:
      - {type: walk_to, character: "w${i}", target: ["${1 + i / 2}", "${-y}"], time: 1.0}
"""


def _err(text: str) -> InputError:
    with pytest.raises(InputError) as ei:
        parse_scenario(text, "rep.yaml")
    return ei.value


def test_repeat_expands_in_order_with_typed_values():
    scn = parse_scenario(BASE, "rep.yaml")
    assert [c.name for c in scn.characters] == ["lead", "w1", "w2", "w3"]
    assert [tuple(c.start.position) for c in scn.characters[1:]] == [(0.0, -1.0), (0.0, 0.5), (0.0, 2.0)]
    targets = [tuple(g.target) for g in scn.goals]
    assert targets == [(1.5, 1.0), (2.0, -0.5), (2.5, -2.0)]


def test_crowd_is_twelve_characters_in_six_couples():
    scn = load_scenario("crowd")
    assert len(scn.characters) == 12 and len(scn.couplings) == 6 and len(scn.goals) == 12
    names = {c.name for c in scn.characters}
    for cp in scn.couplings:
        i = cp.name[len("hold"):]
        assert {h.character for h in cp.between} == {f"adult{i}", f"child{i}"} <= names


@pytest.mark.parametrize("old,new,line,field,words", [
    ('"${y}"]', '"${z}"]', 13, "repeat[0].characters[0].start.position[1]", "unknown variable 'z'"),
    ("y: [-1.0, 0.5, 2.0]", "y: [-1.0, 0.5]", 8, "repeat[0].for.y", "has 2 values but 'i' has 3"),
    ('"${1 + i / 2}"', '"${1 + i ** 2}"', 15, "repeat[0].goals[0].target[0]", "bad expression"),
    ('"${1 + i / 2}"', '"${1 + __import__}"', 15, "repeat[0].goals[0].target[0]", "unknown variable"),
    ("    goals:", "    goal:", 15, "repeat[0].goal", "unknown field 'goal'"),
    ("      i: [1, 2, 3]", "      i: []", 7, "repeat[0].for.i", "list of 1 to 100 values"),
    ("name: w${i}", "name: w${i", 10, "repeat[0].characters[0].name", "unterminated"),
])
def test_repeat_construct_errors_are_located(old, new, line, field, words):
    assert old in BASE
    e = _err(BASE.replace(old, new, 1))
    assert words in e.message
    assert e.location.file == "rep.yaml" and e.location.line == line and e.location.field == field
    assert e.exit_code == 2


def test_error_in_an_expanded_item_points_at_the_template():
    e = _err(BASE.replace("preset: adult_male}\n", "preset: adult_male}\n", 1).replace(
        "        style: walk\n", "        style: no_such_style\n", 1))
    assert e.location.line == 12  # the template's style line
    assert e.location.field.startswith("characters[1].style")


def test_duplicate_names_from_a_repeat_are_rejected():
    e = _err(BASE.replace("name: w${i}", "name: w"))
    assert "characters[2]" in (e.location.field or "") or "duplicate" in e.message.lower() or "unique" in e.message


# --- sweeps --------------------------------------------------------------------------------------

def test_values_ranges_and_lists():
    assert parse_values("0:180:20") == tuple(range(0, 181, 20))
    assert parse_values("2.5,3.0,3.5") == (2.5, 3.0, 3.5)
    assert parse_values("0:0.3:0.1") == (0.0, 0.1, 0.2, 0.3)
    assert parse_values("walk,walk_person2") == ("walk", "walk_person2")
    assert parse_path("characters[0].start.heading") == ("characters", 0, "start", "heading")
    for bad in ("0:10:0", "10:0:1", "a:b:c", "1,,2"):
        with pytest.raises(InputError):
            parse_values(bad)
    with pytest.raises(InputError):
        parse_vary("characters[0].start.heading")  # no '='
    with pytest.raises(InputError):
        parse_path("characters[x]")


def test_combinations_first_varies_slowest():
    combos = combinations([parse_vary("a=1,2"), parse_vary("b=x,y,z")])
    assert combos == [(("a", 1), ("b", b)) for b in "xyz"] + [(("a", 2), ("b", b)) for b in "xyz"]
    with pytest.raises(InputError):
        combinations([parse_vary("a=1,2"), parse_vary("a=3")])


def test_variants_apply_the_values_and_validate():
    vs = build_variants("walk", [parse_vary("characters[0].start.heading=0:0.2:0.1"),
                                 parse_vary("characters[0].style=walk,walk_person2")])
    assert len(vs) == 6
    d = yaml.safe_load(vs[5].yaml_text)
    assert d["characters"][0]["start"]["heading"] == pytest.approx(0.2)
    assert d["characters"][0]["style"] == "walk_person2"
    assert vs[5].assignment == (("characters[0].start.heading", 0.2), ("characters[0].style", "walk_person2"))


@pytest.mark.parametrize("vary,words,field", [
    ("characters[3].start.heading=0,1", "characters has 1 item(s), no [3]", "characters[3].start.heading"),
    ("characters[0].strat.heading=0,1", "has no field 'strat'", "characters[0].strat.heading"),
    ("characters[0].start.heading=0,east", "variant 1", "characters[0].start.heading"),
    ("duration=1.2,-1", "variant 1: duration=-1", "duration"),
])
def test_bad_variants_are_located_errors(vary, words, field):
    with pytest.raises(InputError) as ei:
        build_variants("walk", [parse_vary(vary)])
    e = ei.value
    assert words in str(e)
    assert e.location.file.endswith("walk.yaml") and e.location.line is not None
    assert e.location.field == field


def test_sweep_command_rejects_a_bad_combination_before_writing(tmp_path, capsys):
    out = tmp_path / "sw"
    rc = cli.main(["sweep", "walk", "--vary", "characters[0].start.heading=0,east", "-o", str(out)])
    assert rc == 2
    assert "walk.yaml:" in capsys.readouterr().err
    assert not out.exists()


def test_sweep_refuses_a_folder_holding_another_sweep(tmp_path, capsys):
    out = tmp_path / "sw"
    out.mkdir()
    (out / "sweep.json").write_text('{"format": 1, "variants": []}')
    assert cli.main(["sweep", "walk", "--vary", "duration=1.2", "-o", str(out)]) == 2
    assert "--resume" in capsys.readouterr().err
    assert cli.main(["sweep", "walk", "--vary", "duration=1.2", "-o", str(out), "--resume"]) == 2
    assert "different sweep" in capsys.readouterr().err
