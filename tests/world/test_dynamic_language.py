"""The dynamic-motion language (issue 20): ``jump``, ``hop`` and ``keyframes`` goals.

Validation with located errors, and every field's effect on what is solved: the stages
(footsteps and flights), the flight term of the Step and the zero root residual it becomes
in the transcription, the landing heading of ``turn_deg``, the bounded free footprints of a
region, the obstacle springs and the keyframe springs.  No IPOPT (fast).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from scenarios.errors import InputError
from scenarios.loader import load_scenario, parse_scenario
from scenegraph.problem import PoseTarget, transcribe
from scenegraph.problem.transcription import W_FLIGHT, flight_root_weights
from scenegraph.model.footsteps import contact_points
from scenegraph.model.residual import W_ROOT
from scenegraph.world.scene import build_scene
from schedules.plan.compiler import compile_schedule
from schedules.execution.lower import lower

HEAD = """name: j
duration: 2.0
characters:
  - name: a
    start: {position: [0.0, 0.0], heading: 0}
goals:
"""


def _scn(goals: str, head: str = HEAD):
    return parse_scenario(head + goals, "j.yaml")


def _bad(goals: str, field: str, words: str):
    with pytest.raises(InputError) as e:
        _scn(goals)
    msg = str(e.value)
    assert "j.yaml:" in msg and field in msg and words in msg, msg


JUMP = """  - type: jump
    character: a
    takeoff: {time: 0.8}
    landing: {position: [1.2, 0.0], time: 1.28}
"""


def test_bad_jumps_are_rejected_at_their_field():
    _bad("  - {type: jump, character: a, landing: {time: 1.0}}\n", "goals[0].landing", "position or a region")
    _bad("  - {type: jump, character: a, takeoff: {time: 1.0}, landing: {position: [1, 0], time: 0.9}}\n",
         "goals[0].landing.time", "after the take-off")
    _bad("  - {type: jump, character: a, takeoff: {position: [2, 0]}, landing: {position: [3, 0]}}\n",
         "goals[0].takeoff.position", "where the character stands")
    _bad("  - {type: jump, character: a, landing: {position: [1, 0], time: 2.5}}\n", "goals[0].landing", "")
    _bad("  - {type: jump, character: a, landing: {position: [1, 0], region: {min: [0, 0], max: [1, 1]}}}\n",
         "goals[0].landing.region", "not both")
    _bad("  - {type: hop, character: a, landing: {position: [1, 0]}}\n", "goals[0].foot", "")
    _bad("  - {type: jump, character: a, takeoff: {region: {min: [0, 0], max: [1, 1]}}, landing: {position: [1, 0]}}\n",
         "goals[0].takeoff.region", "a region is for landings")
    _bad(JUMP + "  - {type: footprints, character: a, steps: [{foot: l, position: [0, 0.1], time: [1.5, 1.9]}]}\n",
         "goals[1].type", "cannot be combined")
    _bad("  - {type: keyframes, character: a, keys: [{time: 0.5, joints: {knee_flx_l: 40}}]}\n",
         "goals[0].keys[0].joints", "knee_flex_l")
    _bad("  - {type: keyframes, character: a, keys: [{time: 0.5}]}\n", "goals[0].keys[0].time", "position, a heading")


def test_a_jump_is_a_ground_flight_ground_plan_with_a_ballistic_flight_term():
    scn = _scn(JUMP)
    scene = build_scene(scn)
    st = scene.character("a")
    on = lambda t: [f.foot for f in st.footsteps if f.t0 <= t <= f.t1]  # noqa: E731
    assert on(0.5) == ["l", "r"] and on(1.0) == [] and sorted(on(1.5)) == ["l", "r"]
    sched = compile_schedule(scn)
    full = [s for s in sched.order() if s.kind == "full"][0]
    assert full.term("flight:jump_0") == "hard"
    sp, _ = lower(scene, full, "a")
    assert sp.flights == ((0.8, 1.28),)
    s = transcribe(sp, derivatives=False).s_points
    t_s = sp.motion.time(s)  # knots on the flight's ends: the warp is not uniform (scenegraph/model/knot_warp.py)
    inside = (t_s > 0.8 - 1e-6) & (t_s < 1.28 + 1e-6)  # the take-off and touch-down points too
    assert inside.sum() >= 3
    # by default the flight term becomes momentum equalities: 6 per evaluation point of the flight
    # (collocation nodes and the midpoints between them, ends included) after the first
    mom = transcribe(sp, derivatives=False)
    (grp,) = [sl for name, sl, kind in mom.groups if name == "flight_momentum"]
    t_ev = sp.motion.time(mom.s_eval)
    in_ev = int(np.sum((t_ev > 0.8 - 1e-6) & (t_ev < 1.28 + 1e-6)))
    assert in_ev == 2 * inside.sum() - 1  # every node of the flight and every midpoint between them
    assert grp.stop - grp.start == 6 * (in_ev - 1)
    # their violation is judged per kilogram of body (m/s, m²/s): the rows are momenta
    from scenegraph.problem.result import violations
    g = np.asarray(mom.g_fn(mom.x0, mom.p0)).ravel()[grp]
    assert np.abs(g).max() > 0.1  # the initial motion is no flight
    assert violations(mom, mom.x0)["flight_momentum"] == pytest.approx(np.abs(g).max() / sp.character.total_mass)
    assert flight_root_weights(sp, s, W_ROOT).max() == W_ROOT  # no stiff term with the equalities
    # the penalty formulation (flight_mode "penalty") makes the root residual stiff (W_FLIGHT) at every
    # evaluation point of the flight; the same grid, the same residuals elsewhere
    nlp = transcribe(replace(sp, flight_mode="penalty"), derivatives=False)
    assert not [n for n, _, _ in nlp.groups if n == "flight_momentum"]
    assert np.array_equal(nlp.s_eval, mom.s_eval)
    rho = np.asarray(nlp.rho_dyn_fn(nlp.x0, nlp.p0)).reshape(-1, 35)  # (N_eval, 35): per point, root last 6
    rho0 = np.asarray(mom.rho_dyn_fn(mom.x0, mom.p0)).reshape(-1, 35)
    t_ev = sp.motion.time(nlp.s_eval)
    inside_ev = (t_ev > 0.8 - 1e-6) & (t_ev < 1.28 + 1e-6)
    assert inside.sum() >= 12
    live = np.abs(rho0[:, 29:]) > 1e-9
    ratio = np.abs(rho[:, 29:]) / np.maximum(np.abs(rho0[:, 29:]), 1e-12)
    assert live[inside_ev].sum() > 12
    assert np.allclose(ratio[inside_ev][live[inside_ev]], np.sqrt(W_FLIGHT / W_ROOT), rtol=1e-6)
    assert np.allclose(rho[~inside_ev], rho0[~inside_ev])
    assert flight_root_weights(replace(sp, flight_mode="penalty"), s, W_ROOT)[inside].min() == W_FLIGHT
    # no contact force at the take-off and touch-down points (nor, densely, at any handle's own touch-down
    # or lift-off); free elsewhere on the ground
    lam = nlp.x_layout["lambda"]
    ub = nlp.ubx[lam].reshape(-1, 4)
    at = sp.motion.time(np.array([s[k] for _, k, _ in nlp.contact_index]))
    edge = (np.abs(at - 0.8) < 1e-6) | (np.abs(at - 1.28) < 1e-6)
    ends = np.array([t for f in st.footsteps for _, span, _ in contact_points(sp.character, f) for t in span])
    at_end = np.array([np.abs(ends - a).min() < 1e-6 for a in at])
    assert edge.any() and np.all(ub[edge] == 0.0) and np.all(np.isinf(ub[~at_end]))
    # the initial motion is ballistic in flight: pelvis height a parabola with g = 9.81
    t = np.linspace(0.85, 1.23, 20)
    z = st.motion.state_at_s(st.motion.to_canonical(t))[0][:, 2]
    a = np.polyfit(t, z, 2)[0]
    assert abs(-2 * a - 9.81) < 0.5


def test_turn_free_timing_region_hop_obstacle_and_keyframes_change_what_is_solved():
    base = build_scene(_scn(JUMP)).character("a").footsteps
    turned = build_scene(_scn(JUMP + "    turn_deg: 90\n")).character("a").footsteps
    assert [f.heading for f in base if f.t0 > 1] == [0.0, 0.0]
    assert [round(f.heading, 6) for f in turned if f.t0 > 1] == [round(math.pi / 2, 6)] * 2
    # a take-off position (within 0.3 m of the start) moves the take-off footprints
    moved = build_scene(_scn(JUMP.replace("takeoff: {time: 0.8}", "takeoff: {position: [0.2, 0.0], time: 0.8}")))
    off = [f.position[0] for f in moved.character("a").footsteps if f.t1 <= 0.8 + 1e-9]
    assert off and all(abs(x - y - 0.2) < 1e-9 for x, y in zip(off, [f.position[0] for f in base if f.t1 <= 0.8 + 1e-9]))
    # free timing: nominal flight from the distance (√(2 d / g)), take-off 0.7 s after the start
    free = build_scene(_scn("  - {type: jump, character: a, landing: {position: [1.2, 0.0]}}\n"))
    g = free.goal("jump_0")
    assert g.t_off == pytest.approx(0.7) and g.t_land - g.t_off == pytest.approx(math.sqrt(2 * 1.2 / 9.81))
    # a landing region: free landing footprints bounded by it
    reg = build_scene(_scn("  - {type: jump, character: a, takeoff: {time: 0.8}, landing: {region: "
                           "{min: [1.0, -0.1], max: [1.4, 0.1]}, time: 1.3}}\n")).character("a").footsteps
    land = [f for f in reg if f.t0 > 1]
    assert all(f.free and f.bounds is not None for f in land)
    # a hop: one foot in the air, the other planted before and after
    hop = build_scene(_scn("  - {type: hop, character: a, foot: l, takeoff: {time: 0.8}, "
                           "landing: {position: [0.6, 0.09], time: 1.15}}\n")).character("a").footsteps
    assert [f.foot for f in hop if f.t0 <= 0.79 <= f.t1] == ["l"]
    assert [f.foot for f in hop if f.t0 <= 1.2 <= f.t1] == ["l"]
    # an obstacle: foot springs at obstacle + margin at mid-flight
    scn = _scn(JUMP + "    obstacle_height: 0.3\n")
    scene = build_scene(scn)
    full = [s for s in compile_schedule(scn).order() if s.kind == "full"][0]
    sp, _ = lower(scene, full, "a")
    obst = [t for t in sp.targets if t.name == "goal:jump_0"]
    assert len(obst) == 4 and all(abs(t.point[2] - 0.35) < 1e-9 and abs(t.t - 1.04) < 1e-9 for t in obst)
    # keyframes: a pelvis spring and a partial pose spring (root yaw and a knee), weighted
    scn = _scn("  - type: keyframes\n    character: a\n    keys:\n"
               "      - {time: 0.5, position: [0.1, 0.0, 0.8], heading: 30, joints: {knee_flex_l: 60}, weight: 2}\n")
    scene = build_scene(scn)
    full = [s for s in compile_schedule(scn).order() if s.kind == "full"][0]
    sp, _ = lower(scene, full, "a")
    w = full.term("goal:keyframes_0")
    assert [(t.handle, t.point, t.weight) for t in sp.targets if t.name == "goal:keyframes_0"] == \
        [("pelvis", (0.1, 0.0, 0.8), 2 * w)]
    (pose,) = sp.poses
    assert isinstance(pose, PoseTarget) and pose.weight == 2 * w and len(pose.dofs) == 2
    assert pose.q[3] == pytest.approx(math.radians(30))


def test_bundled_jumps_load():
    for name in ("broad_jump", "twist_jump"):
        scn = load_scenario(name)
        assert any(g.type == "jump" for g in scn.goals)
