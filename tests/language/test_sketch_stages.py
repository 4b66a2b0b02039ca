"""Stages detected from a keyframe sketch (scenarios/sketch_stages.py; thesis §3.4, issue 20
item 2), on sketches that are not bundled: a long leap (out of the legs' reach), a small hop
in place (free fall at its apex key), a walk (no flight), and what the detection feeds —
the same jump goals, flight terms and footsteps as a stated leap.  No solver (fast).
"""
from __future__ import annotations

import math

import pytest

from scenarios import InputError, parse_scenario
from scenarios.sketch_stages import FREE_FALL, G, detect_flights, reach_speed

HEAD = "name: s\nduration: 2.0\ncharacters:\n  - name: jumper\n    start: {position: [0.0, 0.0], heading: 0}\n"


def _scn(keys: list[str], extra: str = "", head: str = HEAD):
    text = head + "goals:\n  - type: keyframes\n    name: sketch\n    character: jumper\n" + extra + "    keys:\n"
    text += "".join(f"      - {k}\n" for k in keys)
    return parse_scenario(text, "s.yaml")


LEAP = ["{time: 0.6, position: [0.0, 0.0, 0.95]}", "{time: 1.05, position: [1.6, 0.0, 0.95], heading: 30}",
        "{time: 1.6, position: [1.6, 0.0, 0.95], heading: 30}"]
HOP = ["{time: 0.5, position: [0.0, 0.0, 0.93]}", "{time: 0.8, position: [0.0, 0.0, 0.98]}",
       "{time: 0.95, position: [0.05, 0.0, 1.09]}", "{time: 1.1, position: [0.1, 0.0, 0.98]}",
       "{time: 1.5, position: [0.1, 0.0, 0.93]}"]
WALK = [f"{{time: {0.25 * i:.2f}, position: [{0.35 * i:.3f}, 0.0, {0.93 + 0.02 * math.cos(math.pi * i):.3f}]}}"
        for i in range(1, 8)]  # 1.4 m/s with a 2 cm bob per step


def test_the_reach_limit_is_the_walk_run_transition():
    # Froude 0.5 on a leg of 0.530 × stature: 2.13 m/s for 1.75 m, slower for a child
    assert reach_speed(1.75) == pytest.approx(math.sqrt(0.5 * 9.81 * 0.530 * 1.75))
    assert 2.1 < reach_speed(1.75) < 2.2 and reach_speed(1.2) < 1.8
    from scenegraph.model.body import make_character, standing_pose  # the constant is the model's leg
    from scenegraph.model.kinematics import handle_position
    ch = make_character("adult_male", height=1.75)
    q = standing_pose(ch)
    leg = float(handle_position(ch, q, "hip_l")[2]) - float(handle_position(ch, q, "heel_l")[2])
    assert leg == pytest.approx(0.530 * 1.75, abs=1e-9)


def test_a_long_leap_is_detected_out_of_reach():
    scn = _scn(LEAP)
    (st,) = scn.sketch_stages
    assert st["t"] == [0.6, 1.05] and st["keys"] == [0, 1] and st["why"][0].startswith("reach")
    g = scn.goals[-1]
    assert g.type == "jump" and g.name == "sketch_flight_0" and g.character == "jumper"
    assert (g.takeoff.time, g.landing.time, tuple(g.landing.position)) == (0.6, 1.05, (1.6, 0.0))
    assert g.takeoff.position is None  # from where the character stands, not under the leaning pelvis
    assert g.turn_deg == 0.0  # the take-off key gives no heading: no turn is implied
    # the same leap, slower (1.6 m in 0.9 s = 1.8 m/s): walkable, nothing detected
    slow = [LEAP[0], LEAP[1].replace("1.05", "1.5"), LEAP[2].replace("1.6, position", "1.9, position")]
    assert _scn(slow).sketch_stages == []
    # a child (1.2 m) cannot walk 1.8 m/s: the same slow sketch is a leap for it
    child = HEAD.replace("    start:", "    body: {preset: child}\n    start:")
    assert len(_scn(slow, head=child).sketch_stages) == 1


def test_a_small_hop_is_detected_by_free_fall_at_its_apex():
    scn = _scn(HOP)
    (st,) = scn.sketch_stages
    assert st["keys"] == [1, 3] and st["t"] == [0.8, 1.1] and st["why"][0].startswith("free fall")
    # the apex key falls with 2 (0.11/0.15 + 0.11/0.15) / 0.3 = 9.8 m/s² ≈ g: in the air; the take-off key
    # accelerates upward (the push-off), the others are on the ground
    assert scn.goals[-1].landing.position == pytest.approx((0.1, 0.0))
    lower = [k.replace("1.09", "1.0") for k in HOP]  # a 2 cm rise over 0.15 s: 1.8 m/s², a dip, not a flight
    assert _scn(lower).sketch_stages == []


def test_a_walk_has_no_flight():
    scn = _scn(WALK)
    assert scn.sketch_stages == [] and [g.type for g in scn.goals] == ["keyframes"]
    keys = [(0.25 * i, (0.35 * i, 0.0, 0.93 + 0.02 * math.cos(math.pi * i)), None, i) for i in range(1, 8)]
    acc = [2 * (0.04 / 0.25 + 0.04 / 0.25) / 0.5]  # the bob's largest vertical acceleration, m/s²
    assert acc[0] < FREE_FALL * G and detect_flights(keys, 1.75) == []


def test_stated_stages_and_stages_none_are_not_detected():
    assert _scn(LEAP, extra="    stages: none\n").sketch_stages == []
    stated = HEAD + ("goals:\n  - type: jump\n    character: jumper\n    takeoff: {time: 0.5}\n"
                     "    landing: {position: [0.5, 0.0], time: 0.8}\n"
                     "  - type: keyframes\n    character: jumper\n    keys:\n"
                     + "".join(f"      - {k}\n" for k in LEAP).replace("0.6,", "1.1,").replace("1.05,", "1.3,")
                     .replace("1.6, position: [1.6", "1.9, position: [1.6"))
    scn = parse_scenario(stated, "s.yaml")
    assert scn.sketch_stages == [] and [g.type for g in scn.goals] == ["jump", "keyframes"]


def test_a_detected_leap_that_cannot_push_off_is_an_error_at_the_sketch_keys():
    early = [LEAP[0].replace("0.6", "0.1"), LEAP[1].replace("1.05", "0.5"), LEAP[2]]  # take-off at 0.1 s
    with pytest.raises(InputError) as e:
        _scn(early)
    msg = str(e.value)
    assert msg.startswith("s.yaml:11:") and "push off" in msg, msg  # line 11: the take-off key


def test_detected_stages_feed_the_flight_machinery():
    from scenegraph.world.scene import build_scene
    from schedules.plan.compiler import compile_schedule
    scn = _scn(LEAP)
    sched = compile_schedule(scn)
    full = [s for s in sched.steps if s.kind == "full"]
    assert full and all(dict(s.terms).get("flight:sketch_flight_0") is not None for s in full)
    scene = build_scene(scn)
    jump = scene.goal("sketch_flight_0")
    assert jump.flight == (0.6, 1.05)
    me = scene.character("jumper")
    # no footstep is planted in the flight; both feet land at 1.6 m
    inflight = [f for f in me.footsteps if f.t0 < 1.0 and f.t1 > 0.65]
    assert inflight == [], inflight
    assert any(abs(f.position[0] - 1.6) < 0.2 and f.t0 >= 1.05 - 1e-9 for f in me.footsteps)
