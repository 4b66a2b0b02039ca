"""Goals and couplings as typed records (scenegraph/world/goals/): one registry entry per kind of
the scenario language, scenario locations that travel with the records into the report, and
the report line of a goal that does not hold."""
from __future__ import annotations

import re
import typing

import pytest

from scenarios import load_scenario, parse_scenario
from scenarios.schema import Coupling as SchemaCoupling, Goal as SchemaGoal
from scenegraph.world.goals import COUPLING_KINDS, GOAL_KINDS
from scenegraph.world.scene import build_scene
from schedules.cli.run import goal_report, violation_line


def _kinds(annotated) -> set[str]:
    union = typing.get_args(annotated)[0]
    return {typing.get_args(m.model_fields["type"].annotation)[0] for m in typing.get_args(union)}


def test_every_goal_and_coupling_kind_of_the_language_has_exactly_one_record():
    assert set(GOAL_KINDS) == _kinds(SchemaGoal)
    assert set(COUPLING_KINDS) == _kinds(SchemaCoupling)
    for kind, cls in {**GOAL_KINDS, **COUPLING_KINDS}.items():
        assert cls.kind == kind and hasattr(cls, "from_schema")


def test_records_carry_their_scenario_location_and_typed_fields():
    scene = build_scene(load_scenario("tackle"))
    hit, dodge = scene.goal("hit"), scene.goal("dodge")
    assert re.search(r"tackle\.yaml:\d+:5 goals\[0\] \(hit\)$", hit.where), hit.where
    assert dodge.where.endswith("goals[1] (dodge)")
    assert (hit.character, hit.partner, hit.hands_around_torso) == ("tackler", "dodger", True)
    assert dodge.radius > 0 and dodge.partner == "tackler"
    hh = build_scene(load_scenario("handhold")).coupling("hold")
    assert hh.where.endswith("couplings[0] (hold)") and hh.handles == (("adult", "palm_r"), ("child", "palm_l"))


MISSED = """name: miss
duration: 1.0
characters:
  - name: a
goals:
  - type: reach
    character: a
    handle: palm_r
    target: [3.0, 0.0, 1.0]
    time: 0.5
    tolerance: 0.05
"""


def test_a_goal_that_does_not_hold_is_reported_at_its_location():
    # the unsolved initial motion (standing) cannot reach 3 m ahead: the entry and the line say where
    scene = build_scene(parse_scenario(MISSED, "miss.yaml"))
    goals, _ = goal_report(scene, {})
    e = goals["reach_0"]
    assert not e["holds"] and e["where"] == "miss.yaml:6:5 goals[0] (reach_0)"
    line = violation_line("reach goal 'reach_0'", e)
    miss = e["measured"] - 0.05
    assert line.startswith("miss.yaml:6:5 goals[0] (reach_0): reach goal 'reach_0' does NOT hold: measured ")
    assert line.endswith(f"violated by {miss:.3g} m") and miss > 2.0


@pytest.mark.parametrize("name", ["walk_to", "walk", "tackle", "handhold", "walk_to_run"])
def test_every_entry_of_a_bundled_scene_has_a_where(name):
    scene = build_scene(load_scenario(name))
    goals, couplings = goal_report(scene, {c.name: {"footstep_error_max": 0.0} for c in scene.characters})
    for e in [*goals.values(), *couplings.values()]:
        assert re.search(rf"{name}\.yaml:\d+:\d+ (goals|couplings)\[\d+\] \(\w+\)$", e["where"])
        assert isinstance(e["holds"], bool)


def test_an_extra_mass_label_reaches_the_report():
    from schedules.cli.run import extra_mass_entries
    assert extra_mass_entries(load_scenario("suitcase"), "walker") == [
        {"handle": "palm_r", "mass": 3.0, "label": "suitcase"}]
    assert extra_mass_entries(load_scenario("walk"), "walker") == []
