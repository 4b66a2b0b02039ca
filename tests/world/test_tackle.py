"""Tackle and dodge (thesis §6.4.4): the report's adversarial measures and verdict, and the
bundled scenarios `tackle`, `tackle_dodge` and `two_tacklers` end to end (slow).

Fast tests check the measurement geometry (torso surface distance, closing speed) on
constructed motions and the report logic on table rows; the slow ones run each scenario
with `compose run NAME --report r.json` and assert the numbers in its report.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from scenarios import load_scenario, parse_scenario
from scenegraph.model.motion import Motion
from scenegraph.world.goals import Avoid, Tackle
from scenegraph.world.scene import (TACKLE_CONTACT_TOL, adversarial_plans_last, avoid_measure, body_frames,
                              build_scene, chest_front, goal_targets, reach_budget, tackle_measure, torso_distance)
from schedules.cli.run import avoid_entry, goal_verdict, tackle_entry

ROOT = Path(__file__).resolve().parents[2]


# --- geometry of the measures ---------------------------------------------------------------------

@pytest.fixture(scope="module")
def scene():
    return build_scene(load_scenario("tackle"))


def _translated(state, dx, dy, t_slope=0.0):
    """The character's motion moved by (dx, dy) (+ t_slope·t along x: a constant extra velocity)."""
    m = state.motion
    ctrl = np.array(m.ctrl, float)
    ctrl[:, 0] += dx
    ctrl[:, 1] += dy
    if t_slope:
        # control points of a cubic B-spline with a linear function: Greville abscissae
        n = ctrl.shape[0]
        knots = np.r_[np.zeros(3), np.linspace(0, 1, n - 2), np.ones(3)]
        grev = np.array([knots[i + 1:i + 4].mean() for i in range(n)])
        ctrl[:, 0] += t_slope * m.time(grev)
    return replace(state, motion=Motion(ctrl, np.asarray(m.warp, float)))


def test_torso_distance_is_zero_on_the_surface_and_signed(scene):
    her = scene.character("dodger")
    R, c = body_frames(her, "thorax", [0.5])
    semi = np.asarray(her.character.body("thorax").semi_axes)
    for axis in range(3):
        for sgn in (1.0, -1.0):
            p = c[0] + sgn * R[0][:, axis] * semi[axis]
            assert abs(torso_distance(her, p, 0.5)) < 1e-9
    front = c[0] + R[0][:, 0] * (semi[0] + 0.04)
    assert torso_distance(her, front, 0.5) == pytest.approx(0.04, abs=1e-9)
    assert torso_distance(her, c[0], 0.5) < -0.05  # inside


def test_tackle_measure_contact_and_closing_speed(scene):
    """The contact distance is the torso distance of his chest front; giving the target an
    extra constant velocity w along x changes the closing speed by −w·(line of centres)ₓ."""
    him, her = scene.character("tackler"), scene.character("dodger")
    t = 1.0
    m0 = tackle_measure(him, her, t)
    assert m0["contact_distance"] == pytest.approx(torso_distance(her, chest_front(him, [t])[0], t), abs=1e-12)
    assert m0["closing_speed"] > 2.0  # the initial run closes in at about running speed
    faster = _translated(her, -1.0 * t, 0.0, t_slope=1.0)  # same place at t, +1 m/s along x
    m1 = tackle_measure(him, faster, t)
    assert m1["contact_distance"] == pytest.approx(m0["contact_distance"], abs=1e-6)
    _, ca_ = body_frames(him, "thorax", [t])
    _, cb = body_frames(her, "thorax", [t])
    line = (cb[0] - ca_[0])[:2] / np.linalg.norm((cb[0] - ca_[0])[:2])
    assert m1["closing_speed"] - m0["closing_speed"] == pytest.approx(-line[0], abs=0.02)


def test_avoid_measure_is_the_closer_of_pelvis_and_chest(scene):
    him, her = scene.character("tackler"), scene.character("dodger")
    far = _translated(her, 0.0, 5.0)
    assert avoid_measure(far, him, 1.0) > avoid_measure(her, him, 1.0) + 4.0


# --- targets ---------------------------------------------------------------------------------------

def test_targets_respect_the_reaction_time_budget(scene):
    g = scene.goal("hit")
    him = scene.character("tackler")
    assert reach_budget(g, him, None) == pytest.approx(0.5 * 1.0 * 1.0)
    assert reach_budget(g, him, (0.75, 1.0)) == pytest.approx(0.5 * 1.0 * 0.25 ** 2)
    # the target far away: the chest target moves at most the budget from the current chest
    far = replace(scene, characters=tuple(_translated(c, 0.0, 2.0) if c.name == "dodger" else c
                                          for c in scene.characters))
    targets, hard = goal_targets(far, "tackler", ["hit"], window=(0.75, 1.0))
    assert not hard
    chest = [t for t in targets if t.handle == "chest" and t.t == 1.0][0]
    from scenegraph.world.scene import handle_track
    now = handle_track(him, "chest", [1.0])[0]
    assert np.linalg.norm(np.asarray(chest.point) - now) == pytest.approx(0.03125, abs=1e-6)
    handles = sorted(t.handle for t in targets)
    assert handles == ["chest", "chest", "chest", "palm_l", "palm_r"]
    # avoid: escape springs only for handles inside the sphere, soft, within the budget
    targets, hard = goal_targets(scene, "dodger", ["dodge"], window=(0.5, 1.0))
    assert not hard and targets and all(not t.hard for t in targets)
    her = scene.character("dodger")
    for t in targets:
        assert np.linalg.norm(np.asarray(t.point) - handle_track(her, t.handle, [1.0])[0]) <= 0.125 + 1e-9
    targets, _ = goal_targets(far, "dodger", ["dodge"])
    assert targets == ()


def test_plans_last_per_pair():
    base = ("name: t\nduration: 1.0\ncharacters:\n  - name: a\n  - name: b\n  - name: c\ngoals:\n"
            "  - {type: tackle, attacker: a, target: c, time: 1.0}\n"
            "  - {type: avoid, character: c, around: a, radius: 0.5, time: 1.0}\n"
            "  - {type: tackle, attacker: b, target: c, time: 1.0, plans_last: c}\n")
    scn = parse_scenario(base, "t.yaml")
    last = adversarial_plans_last(scn)
    assert last == {frozenset("ac"): "a", frozenset("bc"): "c"}


# --- report entries and verdict ---------------------------------------------------------------------

def _tackle_goal(plans_last="tackler", speed=3.0, min_speed=2.0):
    return Tackle(name="hit", character="tackler", partner="dodger", time=1.0, tolerance=TACKLE_CONTACT_TOL,
                  min_speed=min_speed, hands_around_torso=True, speed=speed, plans_last=plans_last)


def _avoid_goal(plans_last="tackler"):
    return Avoid(name="dodge", character="dodger", partner="tackler", time=1.0, tolerance=1e-3, radius=0.5,
                 plans_last=plans_last)


def _m(d, v):
    return {"contact_distance": d, "closing_speed": v, "contact_point": [0, 0, 1], "chest_to_chest": 0.3,
            "palm_distances": [0.01, 0.02]}


@pytest.mark.parametrize("d,v,speed,min_speed,holds", [
    (0.0, 3.0, 3.0, 2.0, True),
    (0.049, 2.71, 3.0, 2.0, True),      # at the edges: 5 cm, −9.7 %
    (-0.049, 3.29, 3.0, 2.0, True),     # slightly inside the torso counts as touching
    (0.051, 3.0, 3.0, 2.0, False),      # 5.1 cm short
    (-0.06, 3.0, 3.0, 2.0, False),      # buried 6 cm deep
    (0.0, 2.69, 3.0, 2.0, False),       # 10.3 % too slow
    (0.0, 3.31, 3.0, 2.0, False),       # 10.3 % too fast
    (0.0, 5.0, None, 2.0, True),        # no goal speed: min_speed is a lower bound
    (0.0, 1.9, None, 2.0, False),
])
def test_tackle_entry_table(d, v, speed, min_speed, holds):
    e = tackle_entry(_tackle_goal(speed=speed, min_speed=min_speed), _m(d, v))
    assert e["holds"] is holds
    assert e["contact_holds"] is (abs(d) <= 0.05)
    assert e["measured"] == pytest.approx(abs(d)) and e["tolerance"] == 0.05
    assert e["speed"] == v and e["closing_speed"] == v and e["min_speed"] == min_speed
    assert e["goal_speed"] == speed
    assert e["expected_to_hold"] is True and e["plans_last"] == "tackler"


@pytest.mark.parametrize("clearance,holds", [(0.6, True), (0.5, True), (0.4995, True), (0.49, False), (0.2, False)])
def test_avoid_entry_table(clearance, holds):
    e = avoid_entry(_avoid_goal(), clearance)
    assert e["holds"] is holds and e["measured"] == clearance and e["tolerance"] == 0.5
    assert e["expected_to_hold"] is False and "expected to FAIL" in e["note"]


@pytest.mark.parametrize("last,tackle_holds,avoid_holds,winners,as_expected", [
    ("tackler", True, False, True, True),    # tackle: the tackle lands, the dodge fails as expected
    ("tackler", False, False, False, False),  # the winner missed: the run fails
    ("tackler", True, True, True, True),     # both "hold" (loser's goal not expected, but fine)
    ("dodger", False, True, True, True),     # tackle_dodge: the dodge succeeds
    ("dodger", True, False, False, False),
])
def test_goal_verdict_table(last, tackle_holds, avoid_holds, winners, as_expected):
    t = tackle_entry(_tackle_goal(plans_last=last), _m(0.0 if tackle_holds else 0.2, 3.0))
    a = avoid_entry(_avoid_goal(plans_last=last), 0.6 if avoid_holds else 0.3)
    v = goal_verdict({"hit": t, "dodge": a}, {})
    assert v["winners_goals_hold"] is winners
    assert v["goals_as_expected"] is as_expected
    assert v["all_goals_hold"] is (tackle_holds and avoid_holds)
    loser = "dodge" if last == "tackler" else "hit"
    assert set(v["expected_failures"]) == {loser}


def test_goal_verdict_without_adversarial_goals():
    walk = {"w": {"type": "walk_to", "holds": False}}
    v = goal_verdict(walk, {})
    assert v["winners_goals_hold"] is True and v["goals_as_expected"] is False and v["all_goals_hold"] is False
    assert v["expected_failures"] == {}


def test_bundled_goals_know_who_wins():
    for name, last in (("tackle", "tackler"), ("tackle_dodge", "dodger")):
        scene = build_scene(load_scenario(name))
        assert scene.goal("hit").plans_last == last and scene.goal("dodge").plans_last == last
        assert scene.goal("hit").expected_to_hold is (last == "tackler")
        assert scene.goal("dodge").expected_to_hold is (last == "dodger")
    scene = build_scene(load_scenario("two_tacklers"))
    adv = [g for g in scene.goals if g.type in ("tackle", "avoid")]
    assert len({g.character for g in adv if g.type == "tackle"}) == 2
    assert all(g.plans_last == "dodger" for g in adv)
    assert all(g.expected_to_hold is (g.type == "avoid") for g in adv)


# --- end to end (slow) --------------------------------------------------------------------------------

def _run(name: str, tmp_path: Path, *extra: str) -> tuple[subprocess.CompletedProcess, dict]:
    env = dict(os.environ)
    res = subprocess.run([sys.executable, "-m", "schedules.cli.main", "run", name, "--report", "r.json",
                          "-o", f"{name}.usda", "--run-dir", "run", *extra], cwd=tmp_path, env=env,
                         capture_output=True, text=True)
    rep = json.loads((tmp_path / "r.json").read_text()) if (tmp_path / "r.json").exists() else {}
    return res, rep


def _audits_pass(rep: dict):
    for who, c in rep["characters"].items():
        a = c["audit"]
        assert a["passes"], (who, a)
        assert a["root_residual_rel"] <= 0.02 and a["footstep_error_max"] <= 5e-3, (who, a)
        assert a["penetration_max"] <= 1e-2 and a["friction_violation_max"] <= 0.0981, (who, a)
    assert rep["all_audits_pass"] is True


@pytest.mark.slow
def test_tackle_end_to_end(tmp_path):
    res, rep = _run("tackle", tmp_path)
    assert res.returncode == 0, res.stderr[-3000:]
    _audits_pass(rep)
    hit, dodge = rep["goals"]["hit"], rep["goals"]["dodge"]
    assert hit["expected_to_hold"] is True and hit["holds"] is True
    assert abs(hit["contact_distance"]) <= 0.05
    assert abs(hit["closing_speed"] - 3.0) <= 0.3
    assert dodge["expected_to_hold"] is False and dodge["holds"] is False  # the tackler plans last
    assert dodge["clearance"] < 0.5
    assert rep["winners_goals_hold"] is True and rep["goals_as_expected"] is True and rep["passes"] is True
    assert set(rep["expected_failures"]) == {"dodge"}
    assert "expected to fail by design" in res.stderr


@pytest.mark.slow
def test_tackle_dodge_end_to_end(tmp_path):
    res, rep = _run("tackle_dodge", tmp_path)
    assert res.returncode == 0, res.stderr[-3000:]
    _audits_pass(rep)
    hit, dodge = rep["goals"]["hit"], rep["goals"]["dodge"]
    assert dodge["expected_to_hold"] is True and dodge["holds"] is True
    assert dodge["clearance"] >= 0.5 - 1e-3
    assert hit["expected_to_hold"] is False and hit["holds"] is False  # the dodger plans last
    assert rep["winners_goals_hold"] is True and rep["passes"] is True
    assert set(rep["expected_failures"]) == {"hit"}


@pytest.mark.slow
def test_two_tacklers_end_to_end(tmp_path):
    res, rep = _run("two_tacklers", tmp_path, "--jobs", "2")  # the tacklers' steps in parallel (same result)
    assert res.returncode == 0, res.stderr[-3000:]
    _audits_pass(rep)
    avoids = {n: g for n, g in rep["goals"].items() if g["type"] == "avoid"}
    tackles = {n: g for n, g in rep["goals"].items() if g["type"] == "tackle"}
    assert len(avoids) == 2 and len(tackles) == 2
    for g in avoids.values():
        assert g["expected_to_hold"] is True and g["holds"] is True and g["clearance"] >= g["radius"] - 1e-3
    for g in tackles.values():
        assert g["expected_to_hold"] is False
    assert rep["winners_goals_hold"] is True and rep["passes"] is True
