"""Who plans a character's initial footsteps (scenegraph/world/footplan.py): the lowest
``step_rank`` among its goals — footprints, then walk_to, then a tackler's run, then a tackle
or avoid target's walk ahead — and standing when no goal has a say."""
from __future__ import annotations

import math

import numpy as np

from scenarios.loader import parse_scenario
from scenegraph.world.footplan import RANK_CHASE, RANK_FOOTPRINTS, RANK_LEAP, RANK_WALK, RANK_WALK_AHEAD
from scenegraph.world.scene import build_scene

CAST = """name: plan
duration: 1.2
characters:
  - {name: a, style: walk, start: {position: [0.0, 0.0], heading: 0}}
  - {name: b, style: walk, start: {position: [3.0, -1.5], heading: 90}}
goals:
"""


def _scene(goals: str):
    return build_scene(parse_scenario(CAST + goals, "plan.yaml"))


def _travel(c) -> float:
    xy = np.array([f.position for f in c.footsteps])
    return float(np.linalg.norm(xy[-1] - xy[0]))


def test_without_goals_both_characters_stand():
    scene = _scene("  []\n")
    for c in scene.characters:
        assert len(c.footsteps) == 2 and _travel(c) < 0.25  # two planted feet, a foot width apart


def test_walk_to_plans_before_the_tackle_and_the_target_walks_ahead():
    goals = ("  - {type: walk_to, character: a, target: [1.0, 0.5], time: 1.2}\n"
             "  - {type: tackle, attacker: a, target: b, time: 1.0}\n")
    scene = _scene(goals)
    a, b = scene.character("a"), scene.character("b")
    # a's last footsteps stand at its walk_to target, not on a run through the impact point
    last = np.mean([f.position for f in a.footsteps[-2:]], axis=0)
    assert np.linalg.norm(last - [1.0, 0.5]) < 0.25
    # b has no walk of its own: it walks straight ahead (heading 90°: along +y)
    ys = [f.position[1] for f in b.footsteps]
    assert ys[-1] - ys[0] > 1.0 and abs(b.footsteps[-1].position[0] - 3.0) < 0.2


def test_a_tackler_without_a_walk_runs_at_its_target():
    scene = _scene("  - {type: tackle, attacker: a, target: b, time: 1.0}\n")
    a = scene.character("a")
    d = np.array(a.footsteps[-1].position) - np.array(a.footsteps[0].position)
    assert _travel(a) > 2.0  # a run: about 3 m/s for 1.2 s
    # toward where b's chest is at the impact in b's own initial plan (so b was built first)
    from scenegraph.world.measure import handle_track
    aim = handle_track(scene.character("b"), "chest", [1.0])[0][:2] - np.array(a.footsteps[0].position)
    assert abs(math.atan2(d[1], d[0]) - math.atan2(aim[1], aim[0])) < math.radians(5)


def test_ranks_order_the_kinds():
    scn = parse_scenario(CAST + "  - {type: tackle, attacker: a, target: b, time: 1.0}\n"
                         "  - {type: avoid, character: b, around: a, radius: 0.5, time: 1.0}\n"
                         "  - {type: walk_to, character: a, target: [1.0, 0.0], time: 1.2}\n", "plan.yaml")
    scene = build_scene(scn)
    ranks = {(g.kind, who): g.step_rank(who) for g in scene.goals for who in ("a", "b")}
    assert ranks[("walk_to", "a")] == RANK_WALK and ranks[("walk_to", "b")] is None
    assert ranks[("tackle", "a")] == RANK_CHASE and ranks[("tackle", "b")] == RANK_WALK_AHEAD
    assert ranks[("avoid", "b")] == RANK_WALK_AHEAD and ranks[("avoid", "a")] is None
    assert RANK_FOOTPRINTS < RANK_LEAP < RANK_WALK < RANK_CHASE < RANK_WALK_AHEAD


def test_a_gait_change_reshapes_the_walk():
    def steps(gait):
        goals = ("  - {type: walk_to, character: a, target: [3.0, 0.0], time: 1.2}\n"
                 f"  - {{type: style_change, character: a, style: run, time: 0.5, gait: {gait}}}\n")
        return _scene(goals).character("a").footsteps
    run, walk = steps("run"), steps("walk")
    # after the change the run's stances are shorter than the walk's it replaces
    late = lambda fs: [f.t1 - f.t0 for f in fs if f.t0 > 0.5]  # noqa: E731
    assert late(run) and late(walk) and max(late(run)) < 0.75 * min(late(walk))
