"""Plausibility at validation (docs/reliability.md): goals a body cannot meet are rejected with
the reason and the line, and the limits leave room for what a person can do."""
from __future__ import annotations

import pytest

from scenarios.errors import InputError
from scenarios.loader import parse_scenario

HEAD = "name: p\nduration: 2.0\ncharacters:\n  - name: a\n{body}goals:\n"


def _scn(goals: str, body: str = "") -> str:
    return HEAD.format(body=body) + goals


def _reach(target, time=1.0, handle="palm_r"):
    return f"  - {{type: reach, character: a, handle: {handle}, target: {list(target)}, time: {time}}}\n"


def test_reach_height_scales_with_the_body():
    parse_scenario(_scn(_reach((0.3, 0.0, 2.2))), "ok.yaml")  # 1.26 × 1.75 m: overhead
    with pytest.raises(InputError, match=r"bad.yaml:6:\d+ goals\[0\].target: target z = 2.5 m is above the 2.36 m"):
        parse_scenario(_scn(_reach((0.3, 0.0, 2.5))), "bad.yaml")
    tall = "    body: {height: 2.0}\n"
    parse_scenario(_scn(_reach((0.3, 0.0, 2.5)), tall), "ok.yaml")  # 1.25 × 2.0 m
    child = "    body: {preset: child}\n"
    with pytest.raises(InputError, match="above the 1.62 m a 1.2 m tall character reaches"):
        parse_scenario(_scn(_reach((0.3, 0.0, 2.0)), child), "bad.yaml")


def test_reach_out_of_reach_of_the_path():
    walk = "  - {type: walk_to, character: a, target: [6.0, 0.0], time: 1.0}\n"
    # at 0.5 s the pelvis can be anywhere within 6 m of the start and of the target: x = 3 is fine
    parse_scenario(_scn(walk + _reach((3.0, 0.0, 1.0), 0.5)), "ok.yaml")
    # standing still until 2 s at the start: a target 1.2 m away is within an arm and a lean
    parse_scenario(_scn(_reach((1.2, 0.0, 1.0), 0.0)), "ok.yaml")
    with pytest.raises(InputError, match=r"bad.yaml:7:\d+ goals\[1\].target: .*out of reach of a's path: 3 m from "
                                         r"its start position \(0 s\), 0 s from the reach"):
        parse_scenario(_scn(walk + _reach((3.0, 0.0, 1.0), 0.0)), "bad.yaml")
    with pytest.raises(InputError, match=r"goals\[1\].target: .*from goals\[0\]'s target \(1 s\)"):
        parse_scenario(_scn(walk + _reach((-3.0, 0.0, 1.0), 0.9)), "bad.yaml")


def _steps(rows):
    return "  - type: footprints\n    character: a\n    steps:\n" + "".join(
        f"      - {{foot: {f}, position: [{x}, {y}], time: [{t0}, {t1}]}}\n" for f, x, y, t0, t1 in rows)


def test_footprints_at_a_sprint_are_accepted_and_beyond_are_not():
    sprint = [("r", 0.0, -0.1, 0.0, 0.1), ("l", 2.2, 0.1, 0.22, 0.32), ("r", 4.4, -0.1, 0.44, 0.54),
              ("l", 6.6, 0.1, 0.66, 0.76)]  # 2.2 m steps every 0.22 s: 10 m/s with flight phases
    parse_scenario(_scn(_steps(sprint)), "ok.yaml")
    too_far = sprint[:2] + [("r", 8.0, -0.1, 0.44, 0.54)]  # 5.8 m in 0.12 s of flight
    with pytest.raises(InputError, match=r"bad.yaml:11:\d+ goals\[0\].steps\[2\].position: this footprint is 5.803 m "
                                         r"from goals\[0\].steps\[1\]"):
        parse_scenario(_scn(_steps(too_far)), "bad.yaml")
    far_start = [("r", 3.0, -0.1, 0.0, 0.3)]  # the first contact at 0 s, 3 m from the start
    with pytest.raises(InputError, match="from the start position of a"):
        parse_scenario(_scn(_steps(far_start)), "bad.yaml")


def test_intervals_shorter_than_a_collocation_interval():
    ok = [("r", 0.0, -0.1, 0.0, 0.04), ("l", 0.3, 0.1, 0.1, 0.5)]
    parse_scenario(_scn(_steps(ok)), "ok.yaml")  # 0.04 s ≥ 1/30 s
    short = [("r", 0.0, -0.1, 0.0, 0.03), ("l", 0.3, 0.1, 0.1, 0.5)]
    with pytest.raises(InputError, match=r"goals\[0\].steps\[0\].time: a 0.03 s contact is shorter than one "
                                         r"collocation interval"):
        parse_scenario(_scn(_steps(short)), "bad.yaml")
    hold = ("  - name: b\n    start: {position: [0.0, 0.6]}\ncouplings:\n  - type: hand_hold\n"
            "    between: [{character: a, handle: palm_l}, {character: b, handle: palm_r}]\n"
            "    interval: [1.0, 1.02]\n")
    with pytest.raises(InputError, match=r"couplings\[0\].interval: a 0.02 s coupling is shorter"):
        parse_scenario(HEAD.format(body="").replace("goals:\n", "") + hold, "bad.yaml")


def test_tackle_partners_must_be_able_to_meet():
    two = "  - name: b\n    start: {{position: [{x}, 0.0], heading: 180}}\n"
    goal = "goals:\n  - {type: tackle, attacker: a, target: b, time: 1.0}\n"
    text = "name: t\nduration: 1.2\ncharacters:\n  - name: a\n"
    parse_scenario(text + two.format(x=20.0) + goal, "ok.yaml")  # 20 m: two sprinters close it in 1 s
    with pytest.raises(InputError, match=r"goals\[0\].time: a and b start 40 m apart"):
        parse_scenario(text + two.format(x=40.0) + goal, "bad.yaml")
