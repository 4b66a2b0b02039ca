"""The monolithic two-character NLP (scenegraph/problem/joint.py) on a tiny problem: an adult and a
child standing side by side for 0.3 s, holding hands (hard coupling), the child's pelvis
pulled away from the adult by a soft target so the hold carries a real force."""
import numpy as np
import pytest

from scenegraph.model.audit import audit_motion
from scenegraph.model.body import make_character
from scenegraph.model.gait import initial_motion
from scenegraph.problem.joint import JointCoupling, coupling_times, solve_joint
from scenegraph.model.kinematics import handle_positions_fn
from scenegraph.model.footsteps import foot_length as _foot_length, standing_footsteps
from scenegraph.problem import HandleTarget, Subproblem
from scenegraph.model.style import default_style
from scenegraph.problem.synthesis import presolve_kinematics

T = 0.3


def _palm(ch, handle, motion, times):
    q, _, _ = motion.state_at_s(motion.to_canonical(np.asarray(times, float)))
    return np.asarray(handle_positions_fn(ch, (handle,)).map(len(times))(np.atleast_2d(q).T)).T


@pytest.fixture(scope="module")
def joint():
    sps = []
    for preset, y, pull in (("adult_male", 0.3, None), ("child", -0.3, -0.42)):
        ch = make_character(preset)
        st = default_style(ch.total_mass)
        steps = standing_footsteps((0.0, y, 0.0), 0.0, T, _foot_length(ch))
        pre = presolve_kinematics(ch, st, initial_motion(ch, steps, 0.0, T), steps)
        targets = ()
        if pull is not None:  # the child leans away: the hold must pull it back
            pel = np.asarray(pre.motion.canonical([1.0])[0])
            targets = (HandleTarget("pelvis", T, (float(pel[0]), pull, float(pel[2])), 300.0),)
        sps.append(Subproblem(ch, st, pre.motion, steps, free=frozenset({"q"}), targets=targets,
                              soft_pin_hz=120.0, max_iter=150, stall_iterations=25, label=preset))
    cpl = JointCoupling("palm_r", "palm_l", coupling_times((0.0, T), 30.0))
    return sps, cpl, solve_joint(sps[0], sps[1], cpl)


def test_palms_apart_before_and_together_after(joint):
    sps, cpl, jr = joint
    assert jr.success, jr.summary()
    t = np.asarray(cpl.times)
    before = np.linalg.norm(_palm(sps[0].character, "palm_r", sps[0].motion, t)
                            - _palm(sps[1].character, "palm_l", sps[1].motion, t), axis=1)
    assert before.min() > 0.1  # the initial motions do not hold hands
    ra, rb = jr.results
    after = np.linalg.norm(_palm(sps[0].character, "palm_r", ra.motion, t)
                           - _palm(sps[1].character, "palm_l", rb.motion, t), axis=1)
    assert after.max() <= 1e-6, after
    assert jr.gap_max <= 1e-6
    assert ra.violations["footstep"] <= 1e-6 and rb.violations["footstep"] <= 1e-6


def test_coupling_forces_equal_and_opposite(joint):
    _, _, jr = joint
    ta, fa = jr.results[0].contact_forces["palm_r"]
    tb, fb = jr.results[1].contact_forces["palm_l"]
    np.testing.assert_allclose(ta, tb)  # same collocation times (same window, no footstep ends inside)
    np.testing.assert_allclose(fa, -fb, atol=1e-9)
    np.testing.assert_allclose(fa, np.interp(ta, jr.force_times, jr.force[:, 0])[:, None] * [1, 0, 0]
                               + np.interp(ta, jr.force_times, jr.force[:, 1])[:, None] * [0, 1, 0]
                               + np.interp(ta, jr.force_times, jr.force[:, 2])[:, None] * [0, 0, 1], atol=1e-9)
    # a real force through the hold, not a vanishing one (since the footstep rows lost their dependent
    # rows the solve finds a 7x cheaper hold: ~10 N, mostly vertical, where it squeezed 269 N before)
    assert np.linalg.norm(fa, axis=1).max() > 5.0


def test_root_residual_balances_only_with_the_coupling_force(joint):
    """The independent audit re-evaluates each character's equations of motion: they balance
    with the coupling force counted at the palm, and not without it (nor with the wrong sign)."""
    sps, _, jr = joint
    for sp, r, handle in zip(sps, jr.results, ("palm_r", "palm_l")):
        full = audit_motion(sp.character, sp.style, r.motion, r.footsteps, r.contact_forces)
        without = audit_motion(sp.character, sp.style, r.motion, r.footsteps,
                               {h: v for h, v in r.contact_forces.items() if h != handle})
        t, f = r.contact_forces[handle]
        flipped = audit_motion(sp.character, sp.style, r.motion, r.footsteps,
                               {**r.contact_forces, handle: (t, -f)})
        assert full.root_residual_rel <= 1e-3, full
        assert without.root_residual_max > 3 * full.root_residual_max + 1.0, (without, full)
        assert flipped.root_residual_max > 3 * full.root_residual_max + 1.0, (flipped, full)


def test_force_interpolation_and_held_timewarp_required():
    from scenegraph.problem.joint import _interp_matrix

    M = _interp_matrix(np.array([0.0, 0.1, 0.2]), np.array([-0.05, 0.0, 0.05, 0.2, 0.25]))
    np.testing.assert_allclose(M, [[0, 0, 0], [1, 0, 0], [0.5, 0.5, 0], [0, 0, 1], [0, 0, 0]])
    ch = make_character()
    steps = standing_footsteps((0.0, 0.0, 0.0), 0.0, T, _foot_length(ch))
    sp = Subproblem(ch, default_style(ch.total_mass), initial_motion(ch, steps, 0.0, T), steps)  # warp free
    with pytest.raises(ValueError, match="timewarp"):
        solve_joint(sp, sp, JointCoupling("palm_r", "palm_l", coupling_times((0.0, T))))
