"""A character's footsteps planned by several goals in time order (issue 20: run up, leap, run on).

``walk_to`` and ``jump``/``hop`` goals of one character form a sequence
(:func:`scenegraph.world.footplan.plan_sequence`): each plans its own time segment from where
the previous one left the character, the stances of a foot meeting at a seam are joined, and
overlaps are located errors — in the scenario file (schema) or at the goal whose plan
collides (footplan).  No IPOPT (fast).
"""
from __future__ import annotations

import pytest

from scenarios.errors import InputError
from scenarios.loader import load_scenario, parse_scenario
from scenegraph.model.footsteps import contact_points
from scenegraph.world.scene import build_scene

HEAD = """name: s
duration: 2.0
characters:
  - name: a
    style: run
    start: {position: [0.0, 0.0], heading: 0}
goals:
"""
RUN_UP = "  - {type: walk_to, name: up, character: a, target: [1.55, 0.0], time: 0.6}\n"
LEAP = ("  - {type: jump, name: leap, character: a, takeoff: {position: [1.8, 0.0], time: 0.95}, "
        "landing: {position: [3.0, 0.0], time: 1.45}}\n")


def _bad(goals: str, field: str, words: str):
    with pytest.raises(InputError) as e:
        parse_scenario(HEAD + goals, "s.yaml")
    msg = str(e.value)
    assert "s.yaml:" in msg and field in msg and words in msg, msg


def _no_overlap(steps):
    for foot in ("l", "r"):
        mine = sorted((f for f in steps if f.foot == foot), key=lambda f: f.t0)
        for a, b in zip(mine, mine[1:]):
            assert a.t1 <= b.t0 + 1e-9, (a, b)


def test_run_and_leap_plans_run_up_leap_and_run_on_in_time_order():
    scene = build_scene(load_scenario("run_and_leap"))
    me = scene.character("runner")
    steps = me.footsteps
    _no_overlap(steps)
    leap = scene.goal("leap")
    # the run-up's steps are free running stances (ball only) before the gather
    up = [f for f in steps if f.t1 <= 0.5 + 1e-9]
    assert len(up) >= 2 and all(f.free and f.heel is None for f in up)
    # both feet held at the take-off from the run-up's arrival to the take-off, facing the run
    off = [f for f in steps if abs(f.t1 - leap.t_off) < 1e-9]
    assert sorted(f.foot for f in off) == ["l", "r"] and all(not f.free for f in off)
    assert abs(min(f.t0 for f in off) - 0.5) < 1e-9  # the run-up's arrival
    for f in off:  # a foot lifted elsewhere has time to swing over before it comes down
        before = [g.t1 for g in steps if g.foot == f.foot and g.t1 <= f.t0 + 1e-9]
        assert not before or f.t0 - max(before) >= 0.15 - 1e-9, (f, before)
    mid = sum(f.position[0] for f in off) / 2 - 0.5 * (0.2187)  # ball ahead of the feet midpoint by half a foot
    assert abs(mid - leap.takeoff[0]) < 0.05
    # no foot on the ground in flight
    assert not [f for f in steps if f.t0 < leap.t_land - 1e-9 and f.t1 > leap.t_off + 1e-9]
    # landing: the right foot's landing stance runs on into the first running step (joined at the seam)
    land_r = next(f for f in steps if f.foot == "r" and abs(f.t0 - leap.t_land) < 1e-9)
    assert land_r.t1 > leap.t_land + 0.15 + 0.05
    handles = {h for h, _, _ in contact_points(me.character, land_r)}
    assert handles == {"ball_r", "heel_r"}
    # the run on's steps are free and after the landing hold
    on = [f for f in steps if f.t0 > leap.t_land + 0.15 + 1e-9]
    assert on and all(f.free for f in on)
    # the flight term and the obstacle springs reach the solver as for a lone jump
    assert leap.flight == (0.85, 1.4) and leap.obstacle_height == 0.3
    # the initial motion runs up, rises over the flight and runs on
    x = [float(me.motion.at([t])[0][0][0]) for t in (0.0, 0.95, 1.45, 2.0)]
    assert x[0] < x[1] < x[2] < x[3]


def test_sequence_overlaps_are_located_errors():
    # a walk arriving during the leap's push-off, flight or landing hold
    _bad(LEAP + "  - {type: walk_to, character: a, target: [3.2, 0.0], time: 1.5}\n", "goals[1].time",
         "during goals[0]")
    _bad(RUN_UP.replace("0.6}", "0.8}") + LEAP, "goals[0].time", "during goals[1]")
    # leaps without times cannot be ordered among walks
    _bad(RUN_UP + "  - {type: jump, character: a, landing: {position: [3.0, 0.0]}}\n", "goals[1]",
         "take-off or landing time")
    # a take-off far from where the run-up ends
    _bad(RUN_UP + LEAP.replace("[1.8, 0.0]", "[2.4, 0.0]"), "goals[1].takeoff.position", "where the character stands")


def test_a_run_on_that_leaves_sideways_collides_at_the_seam_with_a_located_error():
    scn = parse_scenario(HEAD + RUN_UP + LEAP + "  - {type: walk_to, name: onward, character: a, target: [3.0, 1.5], "
                         "time: 2.0}\n", "s.yaml")
    with pytest.raises(InputError) as e:
        build_scene(scn)
    msg = str(e.value)
    assert "s.yaml:" in msg and "goals[2]" in msg and "planned twice" in msg, msg


def test_a_lone_jump_or_walk_plans_as_before():
    scene = build_scene(load_scenario("broad_jump"))
    steps = scene.character("jumper").footsteps
    assert [(f.foot, f.t0, f.t1) for f in steps] == [("l", 0.0, 0.8), ("r", 0.0, 0.8), ("l", 1.28, 2.0),
                                                      ("r", 1.28, 2.0)]
    walk = build_scene(load_scenario("walk_to")).character(load_scenario("walk_to").characters[0].name)
    _no_overlap(walk.footsteps)
