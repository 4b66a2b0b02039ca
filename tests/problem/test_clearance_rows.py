"""Bodies apart in the transcription and the joint problem (issue #15, item 5): clearance as
hard rows or a one-sided least-squares term; a joint hand-hold turns one side's rows into rows
between the two moving characters (slow: one that solves it)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from scenegraph.model.body import make_character
from scenegraph.model.clearance import BodyClearance, body_spheres, clearance_pairs, sphere_centers
from scenegraph.model.footsteps import foot_length, footsteps_for_walk, standing_footsteps
from scenegraph.model.gait import initial_motion
from scenegraph.model.style import default_style
from scenegraph.problem import Subproblem, transcribe

CH = make_character()
STYLE = default_style(CH.total_mass)


def test_joint_problem_keeps_its_two_characters_apart_with_rows_between_both():
    """A joint (hard hand-hold) build turns a's clearance rows against b into rows between the two
    moving characters and drops b's against a (no IPOPT solve)."""
    from scenegraph.problem.joint import JointCoupling, _split_clearance
    steps = footsteps_for_walk()
    m = initial_motion(CH, steps, steps[1].t0, steps[-1].t0)
    q = np.asarray(m.at([m.start])[0]).reshape(1, -1)
    qb = q.copy()
    qb[0, 1] += 0.3
    cl_a = clearance_pairs(CH, q, CH, qb, [m.start], other="b")
    cl_b = clearance_pairs(CH, qb, CH, q, [m.start], other="a")
    sp_a = replace(Subproblem(CH, STYLE, m, steps), clearance=cl_a)
    sp_b = replace(Subproblem(CH, STYLE, m, steps), clearance=cl_b)
    a2, b2, cross = _split_clearance(sp_a, sp_b, ("a", "b"))
    assert a2.clearance == () and b2.clearance == () and cross == cl_a
    assert all(c.other_sphere >= 0 for c in cross)
    same = _split_clearance(sp_a, sp_b, None)
    assert same[0] is sp_a and same[2] == ()
    assert JointCoupling("palm_r", "palm_l", (0.0, 0.1)).name == "hold"


@pytest.mark.slow
def test_joint_hand_hold_keeps_bodies_apart_between_the_moving_characters():
    """tests/test_joint.py's tiny hand-hold (adult and child side by side, 0.3 s) with the child
    pulled *toward* the adult: the bodies-apart rows between the two hold in the solution (checked
    on the solved motions' spheres, not on the solver's rows)."""
    from scenegraph.problem.joint import JointCoupling, coupling_times, solve_joint
    from scenegraph.problem import HandleTarget
    from scenegraph.problem.synthesis import presolve_kinematics
    T = 0.3
    sps, chars = [], []
    for preset, y, pull in (("adult_male", 0.3, None), ("child", -0.3, 0.05)):
        ch = make_character(preset)
        st = default_style(ch.total_mass)
        steps = standing_footsteps((0.0, y, 0.0), 0.0, T, foot_length(ch))
        pre = presolve_kinematics(ch, st, initial_motion(ch, steps, 0.0, T), steps)
        pel = np.asarray(pre.motion.canonical([1.0])[0])
        targets = () if pull is None else (HandleTarget("pelvis", T, (float(pel[0]), pull, float(pel[2])), 300.0),)
        sps.append(Subproblem(ch, st, pre.motion, steps, free=frozenset({"q"}), targets=targets,
                              soft_pin_hz=120.0, max_iter=150, stall_iterations=25, label=preset))
        chars.append(ch)
    times = np.linspace(0.0, T, 10)
    qs = [np.atleast_2d(sp.motion.at(times)[0]) for sp in sps]
    skip = frozenset((x.body, y.body) for x in body_spheres(chars[0]) for y in body_spheres(chars[1])
                     if x.body in ("hand_r", "forearm_r") or y.body in ("hand_l", "forearm_l"))
    cl = clearance_pairs(chars[0], qs[0], chars[1], qs[1], times, skip, "child", margin=0.3)
    assert cl
    sps[0] = replace(sps[0], clearance=cl)
    cpl = JointCoupling("palm_r", "palm_l", coupling_times((0.0, T), 30.0))
    jr = solve_joint(sps[0], sps[1], cpl, names=("adult", "child"))
    assert jr.success, jr.summary()
    assert jr.violations["clearance"] <= 1e-4
    Ca = sphere_centers(chars[0], np.atleast_2d(jr.results[0].motion.at(times)[0]))
    Cb = sphere_centers(chars[1], np.atleast_2d(jr.results[1].motion.at(times)[0]))
    k = {float(t): i for i, t in enumerate(times)}
    gaps = [np.linalg.norm(Ca[k[c.t], c.sphere] - Cb[k[c.t], c.other_sphere]) - c.radius for c in cl]
    assert min(gaps) >= -1e-3


def test_clearance_rows_hard_or_soft():
    """Subproblem.clearance becomes 'clearance' inequality rows, or with clearance_weight > 0 a
    one-sided least-squares term (no rows): zero when the sphere is clear, its depth when inside."""
    steps = footsteps_for_walk()
    m = initial_motion(CH, steps, steps[1].t0, steps[-1].t0)
    t = float(m.start + 0.1)
    c0 = sphere_centers(CH, np.atleast_2d(m.at([t])[0]))[0][0]
    inside = BodyClearance(0, t, tuple(c0 + [0.0, 0.0, 0.01]), 0.05)  # 4 cm too deep
    sp = replace(Subproblem(CH, STYLE, m, steps), clearance=(inside,))
    hard = transcribe(sp, derivatives=False)
    _, sl, kind = next(g for g in hard.groups if g[0] == "clearance")
    assert kind == "ineq" and sl.stop - sl.start == 1
    assert float(np.asarray(hard.g_fn(hard.x0, hard.p0)).ravel()[sl][0]) == pytest.approx(0.01 ** 2 - 0.05 ** 2, abs=1e-9)
    soft = transcribe(replace(sp, clearance_weight=100.0), derivatives=False)
    assert not any(g[0] == "clearance" for g in soft.groups)
    r_soft = np.asarray(soft.rho_extra_fn(soft.x0, soft.p0)).ravel()
    r_hard = np.asarray(hard.rho_extra_fn(hard.x0, hard.p0)).ravel()
    assert r_soft.size == r_hard.size + 1
    assert abs(r_soft[-1]) == pytest.approx(30.0 * 10.0 * 0.04, rel=1e-6)  # OBJ_SCALE · √w · depth
