"""Which body pairs a scene keeps apart (issue #15, item 5): held hands are exempt only against
the partner's held hand and forearm; a tackle's pair is kept apart until shortly before the
hit (fast: no solve)."""
from __future__ import annotations

import numpy as np

from scenarios.loader import load_scenario
from scenegraph.model.clearance import body_spheres
from scenegraph.world.clearance import scene_clearance
from scenegraph.world.goals.tackle import TOUCH_LEAD
from scenegraph.world.scene import build_scene


def test_held_hands_are_exempt_only_against_the_partners_hand_and_forearm():
    scene = build_scene(load_scenario("handhold"))
    cpl = scene.couplings[0]
    (wa, ha), (wb, hb) = cpl.handles
    a, b = scene.character(wa), scene.character(wb)
    hand_a, hand_b = a.character.handle(ha).body, b.character.handle(hb).body
    forearm_b = "forearm_" + hand_b.rsplit("_", 1)[1]
    forearm_a = "forearm_" + hand_a.rsplit("_", 1)[1]
    cl = scene_clearance(scene, wa, (0.0, 0.5), margin=10.0)  # every pair within 10 m counts
    mine = body_spheres(a.character)
    pairs = {(mine[c.sphere].body, c.other.split("/", 1)[1]) for c in cl}
    assert (hand_a, hand_b) not in pairs and (hand_a, forearm_b) not in pairs and (forearm_a, hand_b) not in pairs
    assert (hand_a, "pelvis") in pairs and ("pelvis", hand_b) in pairs  # a held hand stays off the rest
    assert all(c.other.split("/", 1)[0] == wb for c in cl)
    near = scene_clearance(scene, wa, (0.0, 0.5))  # the default margin: only pairs that come close
    assert 0 < len(near) < len(cl)


def test_a_tackles_pair_is_apart_until_shortly_before_the_hit():
    scene = build_scene(load_scenario("tackle"))
    g = next(g for g in scene.goals if g.touches() is not None)
    who, other = g.touches()
    cl = scene_clearance(scene, who, (0.0, scene.duration), margin=10.0)  # every pair counts
    ts = np.array([c.t for c in cl])
    assert len(ts) and ts.max() <= g.time - TOUCH_LEAD + 1e-9
    assert ts.min() <= 0.05
